"""The command gate at the robot side's edge: nothing bad reaches the hardware.

A :class:`~interfaces.messages.TorqueCommand` is dropped when it has the
wrong number of joints (NaN and inf are already refused when the message is
decoded; checked again here for commands built in-process); torques beyond
the joint limits are clipped to them, and so is a step larger than the
torque-rate limit allows since the last applied command. Every outcome is
counted by reason.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from interfaces.messages import HOLD, TorqueCommand

#: Default torque-rate limit at the robot side [Nm/s]: 10 Nm per ms, for gross errors only (the
#: controller limits its own rate to about 1 Nm/ms).
DEFAULT_TAU_RATE_NM_S = 10_000.0


class CommandGate:
    """Turns a decoded :class:`TorqueCommand` into torques for the hardware, ``"hold"``, or None (dropped).

    Parameters
    ----------
    tau_max : (n,) joint torque limits [Nm].
    counters : shared counters (``commands_applied``, ``commands_clipped``, ``commands_rate_limited``,
        ``commands_dropped_wrong_length``, ``commands_dropped_non_finite``, ``commands_hold``).
    tau_rate_nm_s : torque-rate limit [Nm/s] between two applied commands; ``dt_s`` the cycle [s].
    """

    def __init__(self, tau_max: np.ndarray, counters: Counter, tau_rate_nm_s: float = DEFAULT_TAU_RATE_NM_S,
                 dt_s: float = 0.001) -> None:
        self.tau_max = np.asarray(tau_max, float)
        self.counters = counters
        self.tau = np.zeros_like(self.tau_max)
        self._prev = np.zeros_like(self.tau_max)
        self._have_prev = False
        self._rate = float(tau_rate_nm_s)
        self._max_step = self._rate * float(dt_s)

    def accept(self, cmd: TorqueCommand, elapsed_s: float | None = None) -> np.ndarray | str | None:
        """Clipped torques (n,) [Nm] (a buffer reused by the next call), ``"hold"``, or None if dropped.

        ``elapsed_s`` : time since the last applied command [s] (default one cycle): the rate limit allows
        ``tau_rate_nm_s`` times that, so commands that come late or after skipped periods are not clipped.
        """
        if cmd.mode == HOLD:
            self.counters["commands_hold"] += 1
            self._have_prev = False  # after a brake the controller ramps in; no rate reference
            return HOLD
        if len(cmd.tau_nm) != len(self.tau_max):
            self.counters["commands_dropped_wrong_length"] += 1
            return None
        self.tau[:] = cmd.tau_nm
        if not np.isfinite(self.tau).all():
            self.counters["commands_dropped_non_finite"] += 1
            return None
        if (np.abs(self.tau) > self.tau_max).any():
            self.counters["commands_clipped"] += 1
            np.clip(self.tau, -self.tau_max, self.tau_max, out=self.tau)
        max_step = self._max_step if elapsed_s is None else max(self._max_step, self._rate * elapsed_s)
        if self._have_prev and (np.abs(self.tau - self._prev) > max_step).any():
            self.counters["commands_rate_limited"] += 1
            np.clip(self.tau, self._prev - max_step, self._prev + max_step, out=self.tau)
        self._prev[:] = self.tau
        self._have_prev = True
        self.counters["commands_applied"] += 1
        return self.tau
