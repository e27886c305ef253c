"""The pure parts of the robot side's limits (:mod:`robot.guard`): look-ahead, hysteresis, the FAULT latch, the surface.

Module-level maths on numpy arrays and small state; no clock, no I/O, no
robot model. Magnitudes are (n,) arrays in SI units.
"""

from __future__ import annotations

import numpy as np


def look_ahead_into(x: np.ndarray, d: np.ndarray, out: np.ndarray) -> np.ndarray:
    """One-cycle look-ahead of magnitudes ``x`` (n,) with their last change ``d`` (n,): ``out = x + max(d, 0)``
    (a falling magnitude is no risk: its look-ahead is itself). A trend foresees a steady acceleration only: a
    torque step is for the command's prediction (:meth:`robot.guard_model.ToolMotion.predict`)."""
    np.maximum(d, 0.0, out=out)
    out += x
    return out


def ahead_of(x: float, prev: float) -> float:
    """:func:`look_ahead_into` for one magnitude: ``x + max(x - prev, 0)``."""
    return x + max(x - prev, 0.0)


class Trend:
    """The last sample of an (n,) magnitude, for :func:`look_ahead_into`; every buffer reused."""

    def __init__(self, n: int) -> None:
        self.prev = np.zeros(n)
        self.d = np.zeros(n)  # the last change
        self.ahead = np.zeros(n)
        self._started = False

    def update(self, x: np.ndarray) -> np.ndarray:
        """The look-ahead (n,) of ``x`` (n,) (the first sample looks ahead to itself)."""
        if not self._started:
            self.prev[:] = x
            self._started = True
        np.subtract(x, self.prev, out=self.d)
        look_ahead_into(x, self.d, self.ahead)
        self.prev[:] = x
        return self.ahead


class Band:
    """Hysteresis on a share of a limit: engaged once a share (now or ahead) passes ``on``, released once the share
    now is under ``off`` (``off`` <= ``on``)."""

    def __init__(self, on: float, off: float) -> None:
        self.on, self.off = on, off
        self.engaged = False

    def update(self, share_ahead: float, share_now: float) -> bool:
        """Move the band; True when this sample engaged it (a new episode)."""
        if not self.engaged and share_ahead > self.on:
            self.engaged = True
            return True
        if self.engaged and share_now < self.off:
            self.engaged = False
        return False


class FaultLatch:
    """Latches after ``episodes`` entries within ``window_s`` [s] (robot time); :meth:`release` unlatches."""

    def __init__(self, episodes: int, window_s: float) -> None:
        self.window_s = window_s
        self._times = np.full(max(episodes, 1), -np.inf)  # the last ``episodes`` entry times, a ring [s]
        self._k = 0
        self.latched = False

    def note(self, t_s: float) -> bool:
        """Count an entry at ``t_s`` [s]; True when it latched the fault."""
        times = self._times
        times[self._k % len(times)] = t_s
        self._k += 1
        oldest = times[self._k % len(times)]  # the entry ``episodes - 1`` before this one
        if not self.latched and t_s - oldest <= self.window_s:
            self.latched = True
            return True
        return False

    def release(self) -> None:
        self.latched = False
        self._times[:] = -np.inf


class ContactPlane:
    """The surface the pad last pressed on: where it touched, ``point`` (3,) [m], and the pad's axis there, ``axis``
    (3,) (tool z, into the surface), both world. ``zone_m``: how far off it the pad still counts as near it [m]."""

    def __init__(self, zone_m: float) -> None:
        self.zone_m = zone_m
        self.point = np.zeros(3)
        self.axis = np.zeros(3)
        self.known = False

    def touch(self, p: np.ndarray, z: np.ndarray) -> None:
        """The pad presses at ``p`` (3,) [m] with its axis ``z`` (3,) (unit)."""
        self.point[:] = p
        self.axis[:] = z
        self.known = True

    def near(self, p: np.ndarray) -> bool:
        """Whether the pad centre ``p`` (3,) [m] is within ``zone_m`` of the surface, on the pad's side of it (or in
        it)."""
        if not self.known:
            return False
        a, c = self.axis, self.point
        height = (c[0] - p[0]) * a[0] + (c[1] - p[1]) * a[1] + (c[2] - p[2]) * a[2]  # along the axis, to it [m]
        return height < self.zone_m

    def approach(self, v: np.ndarray, w: np.ndarray, R: np.ndarray, half_size_m: tuple[float, float]) -> float:
        """The fastest speed [m/s] at which a corner of the pad moves towards the surface (negative: away), for the
        pad centre's velocity ``v`` (3,) [m/s], its angular velocity ``w`` (3,) [rad/s] and orientation ``R`` (3, 3)
        (columns: its x, y axes in the plane of the felt), ``half_size_m`` its half extents along them [m].

        A corner at ``r = +-a x +- b y`` moves at ``v + w x r``, towards the surface at
        ``(v + w x r) . n = v . n + r . (n x w)``; the worst corner adds ``a |x . (n x w)| + b |y . (n x w)|``:
        a pad tipped over an edge digs that edge in while its centre hardly moves."""
        n0, n1, n2 = self.axis
        w0, w1, w2 = w
        t0, t1, t2 = n1 * w2 - n2 * w1, n2 * w0 - n0 * w2, n0 * w1 - n1 * w0  # n x w, written out (np.cross: 40 us)
        a, b = half_size_m
        along_x = R[0, 0] * t0 + R[1, 0] * t1 + R[2, 0] * t2
        along_y = R[0, 1] * t0 + R[1, 1] * t1 + R[2, 1] * t2
        return float(v[0] * n0 + v[1] * n1 + v[2] * n2 + a * abs(along_x) + b * abs(along_y))
