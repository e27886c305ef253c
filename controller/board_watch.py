"""The skill executor's watch of the board pose (a part of :class:`~controller.executor.SkillExecutor`, which owns
one): a board out of the arm's reach is refused, one that jumps from the adopted pose is held off until it is
reported again or has held still (then adopted and surveyed), one that moved a little is adopted while the pad holds
in the air; a stain on it out of the arm's reach is skipped."""

from __future__ import annotations

from enum import IntEnum

import numpy as np

from interfaces.messages import Phase
from lampskit.core.planner_types import Stain

from .executor_stage import ACTIVE, HALTED, Stage
from .executor_state import ExecutorState
from .executor_stops import ExecutorStops
from .executor_types import BoardPose
from .free_motion import FreeMotion
from .params import ExecutorParams
from .stain_book import StainBook
from .surface_touch import SurfaceTouch


class Jump(IntEnum):
    """What :meth:`BoardWatch.confirm_jump` found."""

    NONE = 0  #: no jumped pose waits
    PENDING = 1  #: a jumped pose waits, not adopted: hold
    ADOPTED = 2  #: the jumped pose held still and is adopted now: survey it before any approach


class BoardWatch:
    """The board-pose half of :class:`~controller.executor.SkillExecutor`'s inputs: adopts board poses into the
    executor's ``state`` (``board``), moving ``motion``'s held pose along and ``surface``'s touches with them; a
    jump while the skill moves lifts off through ``stops``; closes the stains in ``book`` the arm cannot reach.

    Parameters
    ----------
    state : ExecutorState
        The executor's shared state.
    motion : FreeMotion
        The executor's free motions (its setpoint is the executor's).
    surface : SurfaceTouch
        Where the executor's touches put the board's surface.
    book : StainBook
        The executor's stains.
    stops : ExecutorStops
        The executor's stops.
    params : ExecutorParams
        ``board_reach_m``, ``board_jump_m``, ``board_jump_rad``, ``board_confirm_s``.

    Attributes
    ----------
    note : str
        Why the last board report was not taken ("" none; status).
    """

    def __init__(self, state: ExecutorState, motion: FreeMotion, surface: SurfaceTouch, book: StainBook,
                 stops: ExecutorStops, params: ExecutorParams) -> None:
        self.state = state
        self.motion = motion
        self.surface = surface
        self.book = book
        self.stops = stops
        self.p = params
        self.note = ""
        self._jump: BoardPose | None = None  # a board pose that jumped from the adopted one, not adopted (yet)
        self._jump_since_s = 0.0  # the skill's clock when the jumped pose was first reported [s]
        self._sp = motion.setpoint
        self._reach_board: BoardPose | None = None  # the board the stains' reach was checked on, and which were
        self._reach_checked: set[int] = set()

    def take(self, board: BoardPose) -> bool:
        """A board report (seen: the touches shift its surface): adopt it, or refuse it (out of reach) or hold it off
        (jumped, :meth:`_jumped`); True if its stains are to be taken."""
        st = self.state
        board = self.surface.shifted(board)  # where the touches put the seen board's surface
        why = self._out_of_reach(board)
        if why is not None:
            st.counters["boards_out_of_reach"] += 1
            self.note = why
            return False
        if st.board is None:
            st.board = board
        elif (off := self._jump_of(st.board, board)) is not None:
            self._jumped(board, *off)
            return False
        elif not board.close_to(st.board):
            self._moved(st.board, board)
        if self._jump is not None:
            st.counters["board_jumps_back"] += 1  # the adopted pose is reported again: the jump is over
            self._jump, self.note = None, ""
        return True

    def skip_out_of_reach(self, stains: list[Stain]) -> None:
        """Close every new stain the arm cannot wipe whole (:meth:`FreeMotion.stain_reach_problem`), named and
        counted: it is skipped, never attempted. Each stain is looked at once per adopted board."""
        st = self.state
        board = st.board
        if board is None:  # (none adopted: no stains taken)
            return
        if self._reach_board is not board:
            self._reach_board, self._reach_checked = board, set()
        for s in stains:
            if s.id in self._reach_checked or s.kappa:
                continue
            self._reach_checked.add(s.id)
            why = self.motion.stain_reach_problem(board, s)
            if why is not None:
                self.book.close_out_of_reach(s.id, why)
                st.counters["stains_out_of_reach"] += 1
                st.log.warning("stain %d at (%.2f, %.2f) m on the board is out of the arm's reach, skipped: %s", s.id,
                               *s.centre_m, why)

    def _out_of_reach(self, board: BoardPose) -> str | None:
        centre = board.to_world(np.array([0.5 * board.size_m[0], 0.5 * board.size_m[1], 0.0]))
        d = float(np.linalg.norm(centre))
        if d > self.p.board_reach_m:
            return f"a board centred {d:.2f} m from the robot base is beyond its reach ({self.p.board_reach_m} m)"
        return None

    def _jump_of(self, adopted: BoardPose, board: BoardPose) -> tuple[float, float] | None:
        """(distance [m], turn [rad]) of ``board`` from the adopted one when beyond the jump limits, else None."""
        d = float(np.linalg.norm(board.origin_m - adopted.origin_m))
        c = float(np.clip((np.trace(board.R @ adopted.R.T) - 1.0) / 2.0, -1.0, 1.0))
        a = float(np.arccos(c))
        return (d, a) if d > self.p.board_jump_m or a > self.p.board_jump_rad else None

    def _jumped(self, board: BoardPose, d: float, a: float) -> None:
        """A board pose far from the adopted one (``d`` [m], ``a`` [rad] off it): never adopted at once. Pressing or
        on the way, lift off first (PAUSED); then hold until the adopted pose is reported again, or the new one has
        held still for ``board_confirm_s`` with the pad in the air (:meth:`confirm_jump`)."""
        st = self.state
        if self._jump is None or not board.close_to(self._jump, 0.01, 0.02):
            st.counters["board_jumps"] += 1
            self._jump, self._jump_since_s = board, st.clock_s
            self.note = f"the board pose jumped {d:.2f} m / {np.degrees(a):.1f} deg: not adopted without a new survey"
            st.log.warning("%s", self.note)
        if st.phase in ACTIVE:
            self.stops.stop(Phase.PAUSED, self.note + "; lifting off")

    def confirm_jump(self) -> Jump:
        """In the air, holding: adopt a jumped board that has held still for ``board_confirm_s`` (its surface
        touched anew); until then PAUSED (unless halted)."""
        st = self.state
        adopted, jumped = st.board, self._jump
        if jumped is None or adopted is None:  # (a jump is held off only from an adopted board)
            return Jump.NONE
        if st.clock_s - self._jump_since_s < self.p.board_confirm_s or self._sp.contact:
            if st.phase not in HALTED and st.phase != Phase.PAUSED:
                st.set_phase(Phase.PAUSED, self.note)
            return Jump.PENDING
        new = self.surface.forget(jumped)  # another board, or this one moved: its surface is touched anew
        self.motion.adopt_board(adopted, new)
        st.board, self._jump, self.note = new, None, ""
        st.counters["board_jumps_adopted"] += 1
        st.log.warning("the board's new pose held still for %.1f s: adopted; surveying it", self.p.board_confirm_s)
        return Jump.ADOPTED

    def _moved(self, adopted: BoardPose, board: BoardPose) -> None:
        """Adopt a moved board while holding in the air (the held pose stays where it is in the world)."""
        st = self.state
        if st.stage == Stage.HOLD and not self._sp.contact:
            self.motion.adopt_board(adopted, board)
            st.board = board
            st.counters["board_adopted"] += 1
        else:
            st.counters["board_moved"] += 1
