"""Where the board's surface really is, learnt from the pad's touches (pure; no clock, no I/O).

Perception places the board from a camera; along the viewing ray its pose is the least sure. With the board's
size measured from its markers (``[perception.board] size_m = [0, 0]``) the size and the distance trade off
against each other: on 40 random reachable boards (``lamps campaign --boards random``) the seen board lay
6-20 mm behind the true surface along its normal, its size measured 1-2 % large. The first approach to a
board therefore creeps over ``first_creep_height_m`` (the descent slows there, not at ``creep_height_m``),
and the height at which the pad meets the surface, in the seen board's frame, is the surface's offset along
the normal: every later pose of that board is shifted by it, so later descents, hops and the survey's look
points are where the surface is. A board that jumps and is adopted again (a new survey) is touched anew.

Only the offset along the normal is learnt: one touch says nothing of the board's tilt, and the tilt
perception reports is good to a degree or so (0.04-1.1 deg on the same boards), which the force loop
absorbs in contact.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .executor_types import BoardPose


@dataclass
class SurfaceTouch:
    """The surface's offset along the seen board's normal [m] (positive: in front of the seen board, towards
    the robot), from ``touches`` touches since the board was adopted; at most ``max_offset_m`` either way (a
    larger one is not a pose error but something else touched: not learnt)."""

    max_offset_m: float = 0.05
    offset_m: float = 0.0
    touches: int = 0
    refused: int = 0

    @property
    def untouched(self) -> bool:
        """No touch on this board yet: its surface is where perception says, within perception's error."""
        return self.touches == 0

    def shifted(self, seen: BoardPose) -> BoardPose:
        """The board ``seen`` by perception moved along its normal by the learnt offset (``seen`` if none)."""
        if self.offset_m == 0.0:
            return seen
        return replace(seen, origin_m=seen.origin_m + self.offset_m * seen.normal)

    def touched(self, board: BoardPose, h_m: float) -> BoardPose:
        """The pad met the surface at height ``h_m`` [m] above ``board`` (the shifted board in use): learn it;
        returns the board to use from now on (``board`` again when the touch is refused)."""
        if abs(self.offset_m + h_m) > self.max_offset_m:
            self.refused += 1
            return board
        self.offset_m += h_m
        self.touches += 1
        return replace(board, origin_m=board.origin_m + h_m * board.normal)

    def forget(self, board: BoardPose) -> BoardPose:
        """A new board adopted: the offset no longer holds. Returns ``board`` (shifted by the old offset) as seen."""
        seen = replace(board, origin_m=board.origin_m - self.offset_m * board.normal)
        self.offset_m, self.touches = 0.0, 0
        return seen
