"""When a cell's run has ended, judged from the controller's phase (pure; seconds in).

``lamps up`` and ``lamps record --until done`` (compose) end a run the same
way: the controller DONE for :data:`SETTLE_S` of robot time (longer than the
executor's recheck, so nothing waits for another pass; robot time because
that is the executor's clock: a lock-step cell on a loaded machine runs
slower than the wall), or in FAULT / ESTOP for :data:`FAULT_HOLD_S` of wall
time (an operator may release an e-stop before that; a lost robot has no
clock).
"""

from __future__ import annotations

from dataclasses import dataclass

from interfaces.messages import Phase

#: DONE held this long (s, robot time; wall time for a controller that does not report it) ends the run.
SETTLE_S = 2.5
#: FAULT or ESTOP held this long (s, wall) ends the run.
FAULT_HOLD_S = 5.0


@dataclass
class RunEnd:
    """Feed each controller status; :meth:`update` says ``(outcome, why)`` once the run has ended."""

    settle_s: float = SETTLE_S
    fault_hold_s: float = FAULT_HOLD_S
    _done_since: float | None = None
    _fault_since: float | None = None

    def update(self, phase: Phase, reason: str, now_s: float, robot_s: float = 0.0) -> tuple[str, str] | None:
        """phase, reason : of the newest ControllerStatus; now_s : a monotonic clock (s); robot_s : the status's
        robot time (s; 0: not reported, the DONE watch uses ``now_s``)."""
        done_clock = robot_s if robot_s > 0.0 else now_s
        self._done_since = (self._done_since if self._done_since is not None else done_clock) \
            if phase == Phase.DONE else None
        self._fault_since = (self._fault_since if self._fault_since is not None else now_s) \
            if phase in (Phase.FAULT, Phase.ESTOP) else None
        if self._done_since is not None and done_clock - self._done_since >= self.settle_s:
            return "done", "the controller is DONE" + (f": {reason}" if reason else "")
        if self._fault_since is not None and now_s - self._fault_since >= self.fault_hold_s:
            return "fault", f"controller {phase}: {reason}"
        return None
