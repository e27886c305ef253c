"""How the skill executor stops (a part of :class:`~controller.executor.SkillExecutor`, which owns one): the retreat
at the end of the skill, the stops for safety (PAUSED, FAULT, ESTOP: brake, ramp the force out, lift off, hold), the
lift from a pad found pressing while held in the air, and the look at stains still awaiting kappa."""

from __future__ import annotations

import numpy as np

from interfaces.messages import Phase
from lampskit.core.planner_types import PlannerParams

from .control.limits import OVERRIDE_DOWN_RATE_1_S
from .executor_stage import ACTIVE, RELEASED_N, Stage
from .executor_state import ExecutorState
from .executor_types import ToolState
from .free_motion import FreeMotion
from .params import ExecutorParams, ForceParams
from .stain_book import StainBook

#: Lifts from the measured height in a row before the executor only holds (a wrong normal would press on).
MAX_FORCED_LIFTS = 3
#: The retreat's in-plane stop is planned to at least this share of the planner's jerk bound (see
#: :meth:`ExecutorStops.begin_retreat`).
RETREAT_MIN_JERK_SHARE = 0.25


class ExecutorStops:
    """The stopping half of :class:`~controller.executor.SkillExecutor`: sets the phase and the stage in the
    executor's ``state`` and starts the motions of ``motion``; ``book``: the stains (which await kappa).

    Parameters
    ----------
    state : ExecutorState
        The executor's shared state.
    motion : FreeMotion
        The executor's free motions (its setpoint is the executor's).
    book : StainBook
        The executor's stains.
    params : ExecutorParams
    force : ForceParams
    planner : PlannerParams
        The planner's kinematic bounds, which the retreat's stop keeps.

    Attributes
    ----------
    resume_after_lift : bool
        The stop was released (:meth:`SkillExecutor.clear`) before its lift ended: the executor goes on once the
        pad is off; every stop sets it False.
    """

    def __init__(self, state: ExecutorState, motion: FreeMotion, book: StainBook, params: ExecutorParams,
                 force: ForceParams, planner: PlannerParams) -> None:
        self.state = state
        self.motion = motion
        self.book = book
        self.p = params
        self.f = force
        self.planner = planner
        self.resume_after_lift = False
        self._sp = motion.setpoint
        self._forced_lifts = 0  # lifts from the measured height in a row (a pad pressing while held in the air)

    def begin_retreat(self) -> None:
        """The skill's end (the chain finished): bring the in-plane motion to rest, ramp the force out, then lift."""
        st = self.state
        st.set_phase(Phase.RETREAT, "")
        st.current_mp = "retreat"
        st.stain_id = -1
        st.junction_ticks.append(st.ticks)
        # the end of the skill, not a stop for safety: within the planner's kinematic bounds, taking longer if needed,
        # with room for the speed override's time scaling: the executed jerk gains 2 s (ds/dt) a, up to 2 x 8/s x a
        # at the stroke's acceleration a (campaign cells stopped at 101-105 m/s^3 with 75-100 % of the bound planned)
        jerk = self.planner.max_jerk_m_s3
        room = 2.0 * OVERRIDE_DOWN_RATE_1_S * float(np.linalg.norm(self._sp.a_xy))
        bounds = (self.planner.max_accel_m_s2, max(jerk - room, RETREAT_MIN_JERK_SHARE * jerk))
        st.stage = (Stage.UNPRESS if self.motion.brake(self.p.stop_s, self.f.ramp_s, bounds, st.board)
                    else Stage.BRAKE)

    def stop(self, phase: Phase, reason: str, fast: bool = False) -> None:
        """Brake the in-plane motion, ramp the force out, lift off, hold (PAUSED, FAULT, ESTOP); ``fast``: over
        ``estop_ramp_s``. Held in the air already, only a pad measured pressing lifts."""
        st = self.state
        st.set_phase(phase, reason)
        self.resume_after_lift = False
        st.current_mp = "lift"
        if st.stage == Stage.HOLD and not self._sp.contact:
            if st.last_force_n >= RELEASED_N and st.last_tool is not None:
                self._lift_from_measured(st.last_tool)
            return
        self.motion.stop_turn(self.p.estop_ramp_s if fast else self.p.stop_s)
        self._brake(self.p.estop_ramp_s if fast else self.p.stop_s,
                    self.p.estop_ramp_s if fast else self.f.ramp_s)

    def _brake(self, duration_s: float, force_ramp_s: float) -> None:
        self.state.stage = Stage.UNPRESS if self.motion.brake(duration_s, force_ramp_s) else Stage.BRAKE

    def lift_if_pressing(self, tool: ToolState) -> bool:
        """Holding: a pad measured pressing (``RELEASED_N`` or more) while held in the air, outside the active
        phases, lifts (a stop must end with the pad off the board); True if it does. A released pad resets the
        count of lifts in a row."""
        if tool.force_n >= RELEASED_N and not self._sp.contact and self.state.phase not in ACTIVE:
            self._lift_from_measured(tool)
            return True
        if tool.force_n < RELEASED_N:
            self._forced_lifts = 0
        return False

    def _lift_from_measured(self, tool: ToolState) -> None:
        """Held in the air by the board model but pressing in fact (the model is off): lift ``standoff_m`` above the
        measured height, at most ``MAX_FORCED_LIFTS`` times in a row."""
        if self._forced_lifts >= MAX_FORCED_LIFTS:
            return
        self._forced_lifts += 1
        self.state.counters["lifts_from_a_pressing_hold"] += 1
        self.state.log.warning("the pad presses %.1f N while held in the air: lifting %.0f mm from where it is",
                               tool.force_n, 1e3 * self.p.standoff_m)
        self.motion.lift(tool, from_measured=True)
        self.state.stage = Stage.LIFT

    def begin_lift(self, tool: ToolState) -> None:
        """The pad at rest (and released): lift it to ``standoff_m``."""
        st = self.state
        if not self.motion.lift(tool, board=st.board):
            st.counters["lifts_short_of_a_stretched_arm"] += 1
        if st.phase == Phase.RETREAT:
            st.current_mp = "retreat"
        st.stage = Stage.LIFT

    def begin_look(self) -> bool:
        """Off the stains awaiting kappa, which the arm hid from the camera; False if none wait or no move is needed."""
        st = self.state
        pending = self.book.pending()
        # a stain still waiting after k passes was not seen clean from the k - 1 look points before: another one
        attempt = max((self.book.passes(s.id) for s in pending), default=1) - 1
        if not pending or self.p.look_clearance_m <= 0.0 or st.board is None \
                or not self.motion.fly_to_look(st.board, pending, attempt):
            return False
        st.current_mp = "look"
        st.counters["looks"] += 1
        st.stage = Stage.LOOK
        return True

    def done(self) -> None:
        """DONE, holding; the reason names the stains left without kappa and why (:meth:`StainBook.left_undone`)."""
        self.state.set_phase(Phase.DONE, self.book.left_undone())
        self.state.stage, self.state.current_mp = Stage.HOLD, "hold"
