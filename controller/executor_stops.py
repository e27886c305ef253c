"""How the skill executor stops (a mixin of :class:`~controller.executor.SkillExecutor`): the retreat at the end
of the skill, the stops for safety (PAUSED, FAULT, ESTOP: brake, ramp the force out, lift off, hold), the lift from
a pad found pressing while held in the air, and the look at stains still awaiting kappa."""

from __future__ import annotations

import logging

import numpy as np

from interfaces.messages import Phase

from .control.limits import OVERRIDE_DOWN_RATE_1_S
from .executor_stage import RELEASED_N, Stage
from .executor_types import ToolState

#: The executor's own log (these are its methods).
log = logging.getLogger("controller.executor")

#: Lifts from the measured height in a row before the executor only holds (a wrong normal would press on).
MAX_FORCED_LIFTS = 3
#: The retreat's in-plane stop is planned to at least this share of the planner's jerk bound (see
#: :meth:`_begin_retreat`).
RETREAT_MIN_JERK_SHARE = 0.25


class ExecutorStops:
    """The stopping half of :class:`~controller.executor.SkillExecutor`, which it inherits: uses the executor's
    state (``phase``, ``_stage``, ``motion``, ``book``, ``board``, ``p``, ``f``, ``planner``, ``counters``, ...)
    and its :meth:`_set_phase`."""

    def _begin_retreat(self) -> None:
        self._set_phase(Phase.RETREAT, "")
        self.current_mp = "retreat"
        self.stain_id = -1
        self.junction_ticks.append(self.ticks)
        # the end of the skill, not a stop for safety: within the planner's kinematic bounds, taking longer if needed,
        # with room for the speed override's time scaling: the executed jerk gains 2 s (ds/dt) a, up to 2 x 8/s x a
        # at the stroke's acceleration a (campaign cells stopped at 101-105 m/s^3 with 75-100 % of the bound planned)
        jerk = self.planner.max_jerk_m_s3
        room = 2.0 * OVERRIDE_DOWN_RATE_1_S * float(np.linalg.norm(self._sp.a_xy))
        bounds = (self.planner.max_accel_m_s2, max(jerk - room, RETREAT_MIN_JERK_SHARE * jerk))
        self._stage = (Stage.UNPRESS if self.motion.brake(self.p.stop_s, self.f.ramp_s, bounds, self.board)
                       else Stage.BRAKE)

    def _stop(self, phase: Phase, reason: str, fast: bool = False) -> None:
        """Brake the in-plane motion, ramp the force out, lift off, hold (PAUSED, FAULT, ESTOP)."""
        self._set_phase(phase, reason)
        self._resume_after_lift = False
        self.current_mp = "lift"
        if self._stage == Stage.HOLD and not self._sp.contact:
            if self._last_force_n >= RELEASED_N and self._last_tool is not None:
                self._lift_from_measured(self._last_tool)
            return
        self.motion.stop_turn(self.p.estop_ramp_s if fast else self.p.stop_s)
        self._brake(self.p.estop_ramp_s if fast else self.p.stop_s,
                    self.p.estop_ramp_s if fast else self.f.ramp_s)

    def _brake(self, duration_s: float, force_ramp_s: float) -> None:
        self._stage = Stage.UNPRESS if self.motion.brake(duration_s, force_ramp_s) else Stage.BRAKE

    def _lift_from_measured(self, tool: ToolState) -> None:
        """Held in the air by the board model but pressing in fact (the model is off): lift ``standoff_m`` above the
        measured height, at most ``MAX_FORCED_LIFTS`` times in a row."""
        if self._forced_lifts >= MAX_FORCED_LIFTS:
            return
        self._forced_lifts += 1
        self.counters["lifts_from_a_pressing_hold"] += 1
        log.warning("the pad presses %.1f N while held in the air: lifting %.0f mm from where it is", tool.force_n,
                    1e3 * self.p.standoff_m)
        self.motion.lift(tool, from_measured=True)
        self._stage = Stage.LIFT

    def _begin_lift(self, tool: ToolState) -> None:
        if not self.motion.lift(tool, board=self.board):
            self.counters["lifts_short_of_a_stretched_arm"] += 1
        if self.phase == Phase.RETREAT:
            self.current_mp = "retreat"
        self._stage = Stage.LIFT

    def _begin_look(self) -> bool:
        """Off the stains awaiting kappa, which the arm hid from the camera; False if none wait or no move is needed."""
        pending = self.book.pending()
        # a stain still waiting after k passes was not seen clean from the k - 1 look points before: another one
        attempt = max((self.book.passes(s.id) for s in pending), default=1) - 1
        if not pending or self.p.look_clearance_m <= 0.0 or self.board is None \
                or not self.motion.fly_to_look(self.board, pending, attempt):
            return False
        self.current_mp = "look"
        self.counters["looks"] += 1
        self._stage = Stage.LOOK
        return True

    def _done(self) -> None:
        self._set_phase(Phase.DONE, "")
        self._stage, self.current_mp = Stage.HOLD, "hold"
