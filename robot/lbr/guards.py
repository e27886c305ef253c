"""What the real-robot adapter checks before anything leaves for the robot, and how it estimates velocity.

Pure functions and small state on numpy arrays (joints A1..A7, SI units):

* :func:`guard_trip` returns the first reason a command must not be sent
  (non-finite values, a joint at or heading past its limit within one
  period's motion plus a margin, a joint too fast, a torque over its limit,
  a torque step over the rate limit), naming the joint and the value, or
  None when the command may go.
* :class:`VelocityFilter` estimates joint velocity from FRI's measured
  positions: a finite difference over the state's own sample time, then a
  first-order low-pass at ``cutoff_hz`` (the positions are encoder-quantised,
  so a raw difference at 1 ms is noisy). A gap in the samples restarts it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GuardLimits:
    """The adapter's own limits, tighter than the robot's safety configuration.

    q_min_rad, q_max_rad, dq_max_rad_s, tau_max_nm : (n,) joint limits; margin_rad : distance kept
    from the position limits [rad]; tau_rate_nm_s : torque change allowed per second [Nm/s];
    lookahead_s : how far ahead the position check extrapolates with the velocity [s].
    """

    q_min_rad: np.ndarray
    q_max_rad: np.ndarray
    dq_max_rad_s: np.ndarray
    tau_max_nm: np.ndarray
    margin_rad: float = 0.05
    tau_rate_nm_s: float = 2000.0
    lookahead_s: float = 0.001


def joint_name(i: int) -> str:
    """The stack's name of joint ``i`` (0-based): ``A1`` .. ``A7``."""
    return f"A{i + 1}"


def guard_trip(q: np.ndarray, dq: np.ndarray, tau: np.ndarray, tau_prev: np.ndarray | None, dt_s: float,
               limits: GuardLimits, since_prev_s: float | None = None) -> str | None:
    """The reason ``tau`` (n,) [Nm] must not be sent at ``q``, ``dq`` (n,), or None.

    ``dt_s`` : the robot's period [s] (how far the position check looks ahead); ``tau_prev`` : the last
    command sent, ``since_prev_s`` [s] ago (default ``dt_s``), for the torque-rate check.
    """
    for name, v in (("position", q), ("velocity", dq), ("torque", tau)):
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            return f"non-finite {name} on joint {joint_name(int(bad[0]))}"
    ahead = q + dq * max(dt_s, limits.lookahead_s)
    lo, hi = limits.q_min_rad + limits.margin_rad, limits.q_max_rad - limits.margin_rad
    for i in range(len(q)):
        if not lo[i] <= ahead[i] <= hi[i]:
            side = limits.q_min_rad[i] if ahead[i] < lo[i] else limits.q_max_rad[i]
            return (f"joint {joint_name(i)} at {q[i]:+.3f} rad moving {dq[i]:+.3f} rad/s comes within "
                    f"{limits.margin_rad:g} rad of its limit {side:+.3f} rad")
    over = np.flatnonzero(np.abs(dq) > limits.dq_max_rad_s)
    if over.size:
        i = int(over[0])
        return f"joint {joint_name(i)} velocity {dq[i]:+.3f} rad/s over the limit {limits.dq_max_rad_s[i]:.3f} rad/s"
    over = np.flatnonzero(np.abs(tau) > limits.tau_max_nm)
    if over.size:
        i = int(over[0])
        return f"joint {joint_name(i)} torque {tau[i]:+.1f} Nm over the limit {limits.tau_max_nm[i]:.1f} Nm"
    if tau_prev is not None:
        step = np.abs(tau - tau_prev)
        since = dt_s if since_prev_s is None else max(since_prev_s, dt_s)
        allowed = limits.tau_rate_nm_s * max(since, 1e-4)
        over = np.flatnonzero(step > allowed)
        if over.size:
            i = int(over[0])
            return (f"joint {joint_name(i)} torque step {step[i]:.1f} Nm in {since * 1e3:.1f} ms over the rate limit "
                    f"{limits.tau_rate_nm_s:g} Nm/s")
    return None


class VelocityFilter:
    """Joint velocity [rad/s] from measured positions: finite difference, then a first-order low-pass.

    Parameters
    ----------
    n : joints. cutoff_hz : low-pass corner [Hz]. max_gap_s : a longer gap between samples restarts
    the estimate (velocity 0, no history).
    """

    def __init__(self, n: int, cutoff_hz: float = 80.0, max_gap_s: float = 0.02) -> None:
        self.tau_s = 1.0 / (2.0 * math.pi * cutoff_hz)
        self.max_gap_s = max_gap_s
        self.dq = np.zeros(n)
        self._q = np.zeros(n)
        self._t_ns: int | None = None
        self._raw = np.zeros(n)

    def update(self, q: np.ndarray, t_ns: int) -> np.ndarray:
        """The estimate after the sample ``q`` (n,) [rad] at robot time ``t_ns``; the returned array is reused."""
        if self._t_ns is None or not 0 < (t_ns - self._t_ns) * 1e-9 <= self.max_gap_s:
            if self._t_ns is not None and t_ns == self._t_ns:
                return self.dq  # the same sample again: nothing new
            self.dq[:] = 0.0
        else:
            dt = (t_ns - self._t_ns) * 1e-9
            np.subtract(q, self._q, out=self._raw)
            self._raw /= dt
            a = dt / (dt + self.tau_s)
            self.dq += a * (self._raw - self.dq)
        self._q[:] = q
        self._t_ns = t_ns
        return self.dq
