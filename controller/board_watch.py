"""The skill executor's watch of the board pose (a mixin of :class:`~controller.executor.SkillExecutor`): a board
out of the arm's reach is refused, one that jumps from the adopted pose is held off until it is reported again or
has held still (then adopted and surveyed), one that moved a little is adopted while the pad holds in the air."""

from __future__ import annotations

import logging

import numpy as np

from interfaces.messages import Phase

from .executor_stage import _ACTIVE, _HALTED, Stage
from .executor_types import BoardPose

#: The executor's own log (these are its methods).
log = logging.getLogger("controller.executor")


class BoardWatch:
    """The board-pose half of :class:`~controller.executor.SkillExecutor`'s inputs, which it inherits: uses the
    executor's state (``board``, ``_jump``, ``_jump_since_s``, ``board_note``, ``phase``, ``motion``, ``p``,
    ``counters``, ...) and its :meth:`_stop`, :meth:`_set_phase`, :meth:`_survey_or_start`."""

    def _out_of_reach(self, board: BoardPose) -> str | None:
        centre = board.to_world(np.array([0.5 * board.size_m[0], 0.5 * board.size_m[1], 0.0]))
        d = float(np.linalg.norm(centre))
        if d > self.p.board_reach_m:
            return f"a board centred {d:.2f} m from the robot base is beyond its reach ({self.p.board_reach_m} m)"
        return None

    def _jump_of(self, board: BoardPose) -> tuple[float, float] | None:
        """(distance [m], turn [rad]) of ``board`` from the adopted one when beyond the jump limits, else None."""
        d = float(np.linalg.norm(board.origin_m - self.board.origin_m))
        c = float(np.clip((np.trace(board.R @ self.board.R.T) - 1.0) / 2.0, -1.0, 1.0))
        a = float(np.arccos(c))
        return (d, a) if d > self.p.board_jump_m or a > self.p.board_jump_rad else None

    def _board_jumped(self, board: BoardPose) -> None:
        """A board pose far from the adopted one: never adopted at once. Pressing or on the way, lift off first
        (PAUSED); then hold until the adopted pose is reported again, or the new one has held still for
        ``board_confirm_s`` with the pad in the air: adopted then, and surveyed before any approach."""
        d, a = self._jump_of(board)
        if self._jump is None or not board.close_to(self._jump, 0.01, 0.02):
            self.counters["board_jumps"] += 1
            self._jump, self._jump_since_s = board, self.clock_s
            self.board_note = (f"the board pose jumped {d:.2f} m / {np.degrees(a):.1f} deg: not adopted without a "
                               "new survey")
            log.warning("%s", self.board_note)
        if self.phase in _ACTIVE:
            self._stop(Phase.PAUSED, self.board_note + "; lifting off")

    def _confirm_jump(self) -> bool:
        """In the air, holding: adopt a jumped board that has held still long enough; True while one is pending."""
        if self._jump is None:
            return False
        if self.clock_s - self._jump_since_s < self.p.board_confirm_s or self._sp.contact:
            if self.phase not in _HALTED and self.phase != Phase.PAUSED:
                self._set_phase(Phase.PAUSED, self.board_note)
            return True
        new = self.surface.forget(self._jump)  # another board, or this one moved: its surface is touched anew
        self.motion.adopt_board(self.board, new)
        self.board, self._jump, self.board_note = new, None, ""
        self.counters["board_jumps_adopted"] += 1
        self._surveyed = False  # the new pose is surveyed before any approach
        log.warning("the board's new pose held still for %.1f s: adopted; surveying it", self.p.board_confirm_s)
        if self.phase == Phase.PAUSED and self.stains_fresh and self._estop is None:
            self._survey_or_start()
        return self._jump is not None

    def _board_moved(self, board: BoardPose) -> None:
        """Adopt a moved board while holding in the air (the held pose stays where it is in the world)."""
        if self._stage == Stage.HOLD and not self._sp.contact:
            self.motion.adopt_board(self.board, board)
            self.board = board
            self.counters["board_adopted"] += 1
        else:
            self.counters["board_moved"] += 1
