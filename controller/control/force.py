"""Contact force along the board normal: a PI regulator with feed-forward, and the force cap watch.

The pad presses on the board with ``F_cmd = F_ref + kp (F_ref - F) + ki int(F_ref - F) dt``
[N] along the inward normal, where F is the measured normal force (the
board's push on the eraser, along the outward normal). The integral is
clamped (anti-windup) and only runs while in contact, F_cmd stays within
``[0, cap]``. The measured force is low-pass filtered before the cap test
so a single-tick contact spike does not fault the controller, while a
sustained overload does within a few milliseconds.
"""

from __future__ import annotations

import math


class NormalForceRegulator:
    """PI + feed-forward normal force regulator.

    Parameters
    ----------
    kp, ki : float
        Proportional gain [N/N] and integral gain [1/s].
    integral_limit_n : float
        Clamp of the integral term [N].
    cap_n : float
        Force cap [N]: the command never exceeds it and a filtered measurement above it trips :attr:`over_cap`.
    filter_s : float
        Time constant of the measurement filter used for the cap test [s].
    """

    def __init__(self, kp: float, ki: float, integral_limit_n: float, cap_n: float, filter_s: float = 0.005) -> None:
        self.kp, self.ki = float(kp), float(ki)
        self.integral_limit = float(integral_limit_n)
        self.cap = float(cap_n)
        self.filter_s = float(filter_s)
        self.integral = 0.0
        self.filtered_n = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def measure(self, force_n: float, dt_s: float) -> float:
        """Feed a measured normal force [N]; returns the filtered value."""
        a = 1.0 - math.exp(-dt_s / self.filter_s) if self.filter_s > 0 else 1.0
        self.filtered_n += a * (force_n - self.filtered_n)
        return self.filtered_n

    @property
    def over_cap(self) -> bool:
        return self.filtered_n > self.cap

    def command(self, target_n: float, force_n: float, dt_s: float, in_contact: bool) -> float:
        """Force [N] to press with (>= 0, <= cap) for a target and a measurement."""
        err = target_n - force_n
        if in_contact:
            self.integral = min(max(self.integral + self.ki * err * dt_s, -self.integral_limit), self.integral_limit)
        return min(max(target_n + self.kp * err + self.integral, 0.0), self.cap)
