"""Smooth free motions of the skill executor: quintic segments and orientation blends (pure maths).

The learned MPs move the pad *in* the board plane. Everything else the
executor does (fly to a hover point, descend, lift off, brake an in-plane
motion to rest) is a :class:`Quintic`: the unique fifth-order polynomial
meeting given position, velocity and acceleration at both ends, so a
motion that starts where the last one left off is continuous in
acceleration (C2) at the hand-over. :class:`OrientationBlend` turns the pad
from one orientation to another along the geodesic with a quintic time law;
:class:`SmoothRamp` moves a scalar (the force target) along a smoothstep.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba as nb
import numpy as np
import pinocchio as pin

from arm.pad_turn import turn_vector


class Quintic:
    """x(t) for t in [0, T] with x, dx, ddx given at both ends; held (at rest or constant acceleration) after T.

    Parameters
    ----------
    start, goal : (position, velocity, acceleration), arrays of shape (n,)
    duration_s : float
        T [s], > 0.
    """

    def __init__(self, start, goal, duration_s: float) -> None:
        if not (math.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"duration_s must be finite and > 0, got {duration_s!r}")
        p0, v0, a0 = (np.asarray(x, float).reshape(-1) for x in start)
        p1, v1, a1 = (np.asarray(x, float).reshape(-1) for x in goal)
        T = float(duration_s)
        self.T = T
        self.goal = (p1.copy(), v1.copy(), a1.copy())
        # x(t) = c0 + c1 t + ... + c5 t^5
        d = p1 - p0 - v0 * T - 0.5 * a0 * T * T
        dv = v1 - v0 - a0 * T
        da = a1 - a0
        c3 = (10 * d - 4 * dv * T + 0.5 * da * T * T) / T**3
        c4 = (-15 * d + 7 * dv * T - da * T * T) / T**4
        c5 = (6 * d - 3 * dv * T + 0.5 * da * T * T) / T**5
        self._c = np.stack([p0, v0, 0.5 * a0, c3, c4, c5])  # (6, n)
        self.position = p0.copy()
        self.velocity = v0.copy()
        self.acceleration = a0.copy()
        self.time_s = 0.0

    @property
    def finished(self) -> bool:
        return self.time_s >= self.T - 1e-12

    def peaks(self, samples: int = 65) -> tuple[float, float]:
        """The largest acceleration [m/s^2] and jerk [m/s^3] (vector norms) over [0, T], on ``samples`` points."""
        t = np.linspace(0.0, self.T, samples)[:, None]
        c = self._c
        acc = 2 * c[2] + 6 * c[3] * t + 12 * c[4] * t**2 + 20 * c[5] * t**3
        jerk = 6 * c[3] + 24 * c[4] * t + 60 * c[5] * t**2
        return float(np.linalg.norm(acc, axis=1).max()), float(np.linalg.norm(jerk, axis=1).max())

    def update(self, dt_s: float) -> None:
        """Advance by ``dt_s`` [s] and refresh position, velocity, acceleration (one compiled call)."""
        self.time_s += dt_s
        p1, v1, a1 = self.goal
        _quintic_into(self._c, self.time_s, self.T, p1, v1, a1, self.position, self.velocity, self.acceleration)


@nb.njit(cache=True)  # keeps the GIL, as controller/control/kernels.py explains
def _quintic_into(c: np.ndarray, t: float, T: float, p1: np.ndarray, v1: np.ndarray, a1: np.ndarray,
                  position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray) -> None:
    """x, dx, ddx (n,) of ``x(t) = sum c_k t^k`` (c (6, n)) for t < T; after T the goal (p1, v1, a1 (n,)) held
    at constant acceleration."""
    if t >= T:
        u = t - T
        for i in range(position.shape[0]):
            position[i] = p1[i] + v1[i] * u + 0.5 * a1[i] * u * u
            velocity[i] = v1[i] + a1[i] * u
            acceleration[i] = a1[i]
        return
    for i in range(position.shape[0]):
        position[i] = c[0, i] + t * (c[1, i] + t * (c[2, i] + t * (c[3, i] + t * (c[4, i] + t * c[5, i]))))
        velocity[i] = c[1, i] + t * (2 * c[2, i] + t * (3 * c[3, i] + t * (4 * c[4, i] + t * 5 * c[5, i])))
        acceleration[i] = 2 * c[2, i] + t * (6 * c[3, i] + t * (12 * c[4, i] + t * 20 * c[5, i]))


def rest_to_rest(p0: np.ndarray, p1: np.ndarray, mean_speed_m_s: float, min_duration_s: float = 0.2) -> Quintic:
    """A quintic from rest at ``p0`` to rest at ``p1`` with the given mean speed (never shorter than the floor)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    z = np.zeros_like(p0)
    T = max(float(np.linalg.norm(p1 - p0)) / mean_speed_m_s, min_duration_s)
    return Quintic((p0, z, z), (p1, z, z), T)


def brake_to_rest(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, duration_s: float) -> Quintic:
    """Bring a moving point to rest C2-continuously, stopping ``v0 T / 2`` ahead (about where it would coast to)."""
    p0, v0, a0 = (np.asarray(x, float) for x in (p0, v0, a0))
    z = np.zeros_like(p0)
    return Quintic((p0, v0, a0), (p0 + 0.5 * v0 * duration_s, z, z), duration_s)


#: Normalised time tau = t / T of the samples a brake's peaks are checked on (as :meth:`Quintic.peaks`).
_BRAKE_TAU = np.linspace(0.0, 1.0, 65)[:, None]
#: :func:`brake_to_rest` in closed form, with u = 1 / T: jerk(tau) = u^2 v0 G + u a0 H, acc(tau) = a0 K + u v0 M.
_BRAKE_G = 12.0 * _BRAKE_TAU - 6.0
_BRAKE_H = -9.0 + 36.0 * _BRAKE_TAU - 30.0 * _BRAKE_TAU**2
_BRAKE_K = 1.0 - 9.0 * _BRAKE_TAU + 18.0 * _BRAKE_TAU**2 - 10.0 * _BRAKE_TAU**3
_BRAKE_M = 6.0 * _BRAKE_TAU**2 - 6.0 * _BRAKE_TAU


def brake_peaks(v0: np.ndarray, a0: np.ndarray, durations_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The largest acceleration [m/s^2] and jerk [m/s^3] of :func:`brake_to_rest` from velocity ``v0`` and
    acceleration ``a0`` (n,) over each of ``durations_s`` (k,) [s], on :meth:`Quintic.peaks`' samples, in closed
    form: the stop is ``v0 T / 2`` ahead, so its coefficients are those of ``v0`` and ``a0`` times powers of
    ``1 / T`` (no quintic built). Returns two (k,) arrays."""
    u = 1.0 / np.asarray(durations_s, float)[:, None, None]  # (k, 1, 1)
    v0, a0 = np.asarray(v0, float), np.asarray(a0, float)
    jerk = u * u * (_BRAKE_G * v0) + u * (_BRAKE_H * a0)  # (k, samples, n)
    acc = _BRAKE_K * a0 + u * (_BRAKE_M * v0)
    return np.linalg.norm(acc, axis=2).max(axis=1), np.linalg.norm(jerk, axis=2).max(axis=1)


def bounded_brake_to_rest(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, duration_s: float, max_accel_m_s2: float,
                          max_jerk_m_s3: float, stretch: float = 1.2, tries: int = 20,
                          reachable: Callable[[np.ndarray], bool] | None = None) -> Quintic:
    """:func:`brake_to_rest` over ``duration_s`` [s], or longer (``stretch`` times per try) until its acceleration
    and jerk stay within the bounds (the acceleration it starts with excepted); the last try if none does.

    ``reachable(stop) -> bool``: where a brake may end (the arm's reach, the board); a longer brake coasts
    further (``v0 T / 2``), so the first try within the bounds that ends where it may, else the first that ends
    where it may even beyond the bounds (reach before smoothness), else ``duration_s``.

    All tries are checked at once in closed form (:func:`brake_peaks`), then one quintic is built: it runs in the
    tick the retreat starts, where building and sampling a quintic per try took 4x longer (p50 about 400 us
    against 100 us for 400 random stroke states on the loaded 2-core machine, up to 20 tries each)."""
    start = float(np.linalg.norm(a0))
    durations = float(duration_s) * float(stretch) ** np.arange(tries)
    acc, jerk = brake_peaks(v0, a0, durations)
    within = (jerk <= max_jerk_m_s3) & (acc <= max(max_accel_m_s2, start))
    if reachable is None:
        ok = np.flatnonzero(within)
        return brake_to_rest(p0, v0, a0, float(durations[ok[0]] if ok.size else durations[-1]))
    p0, v0 = np.asarray(p0, float), np.asarray(v0, float)
    ends = np.array([reachable(p0 + 0.5 * v0 * T) for T in durations])
    for pick in (within & ends, ends):
        ok = np.flatnonzero(pick)
        if ok.size:
            return brake_to_rest(p0, v0, a0, float(durations[ok[0]]))
    return brake_to_rest(p0, v0, a0, float(durations[0]))


def vertical_move(xy_m: np.ndarray, h0_m: float, h1_m: float, duration_s: float, v0_m_s: float = 0.0,
                  v1_m_s: float = 0.0) -> Quintic:
    """A quintic in (x, y, h): ``xy_m`` (2,) held, h from ``h0_m`` [m] moving at ``v0_m_s`` to ``h1_m`` moving at
    ``v1_m_s`` [m/s] (default: at rest), without acceleration at either end; after it, on at ``v1_m_s``."""
    z = np.zeros(3)
    return Quintic((np.array([*xy_m, h0_m]), np.array([0.0, 0.0, v0_m_s]), z),
                   (np.array([*xy_m, h1_m]), np.array([0.0, 0.0, v1_m_s]), z), duration_s)


def brake_above(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, duration_s: float) -> Quintic:
    """As :func:`brake_to_rest` for (x, y, h) (3,), but never stopping below the start height ``p0[2]``.

    A brake while descending must not carry the pad on into the board.
    """
    goal = p0 + 0.5 * v0 * duration_s
    goal[2] = max(goal[2], p0[2])
    return Quintic((p0, v0, a0), (goal, np.zeros(3), np.zeros(3)), duration_s)


class SmoothRamp:
    """A scalar from ``start`` to ``goal`` over ``duration_s`` along the smoothstep s^2 (3 - 2 s), s in [0, 1]."""

    def __init__(self) -> None:
        self.start = self.goal = 0.0
        self.s = 0.0
        self.duration_s = 1.0

    def restart(self, start: float, goal: float, duration_s: float) -> None:
        self.start, self.goal = start, float(goal)
        self.s, self.duration_s = 0.0, float(duration_s)

    def update(self, dt_s: float) -> float:
        """Advance by ``dt_s`` [s]; the value now (``goal`` once :attr:`finished`)."""
        self.s = min(self.s + dt_s / self.duration_s, 1.0)
        s = self.s
        return self.start + (self.goal - self.start) * s * s * (3.0 - 2.0 * s)

    @property
    def finished(self) -> bool:
        return self.s >= 1.0


class OrientationBlend:
    """R(t) = R0 exp(s(t) log(R0^T R1)) with s a rest-to-rest quintic from 0 to 1 over ``duration_s``; with
    ``about_z`` +1 / -1 the log taken the way round the body's z of that sign (:func:`arm.pad_turn.turn_vector`: a
    half turn of the pad goes the way that takes A7 to the middle of its range).

    Attributes after :meth:`update`: ``R`` (3, 3), ``omega`` (3,) [rad/s]
    and ``domega`` (3,) [rad/s^2], world axes.
    """

    def __init__(self, R0: np.ndarray, R1: np.ndarray, duration_s: float, about_z: float = 0.0) -> None:
        self.R0 = np.asarray(R0, float).copy()
        self.theta = turn_vector(self.R0, R1, about_z)  # body axis-angle
        self._s = Quintic((np.zeros(1), np.zeros(1), np.zeros(1)), (np.ones(1), np.zeros(1), np.zeros(1)), duration_s)
        self.R = self.R0.copy()
        self.omega = np.zeros(3)
        self.domega = np.zeros(3)

    @property
    def finished(self) -> bool:
        return self._s.finished

    def stop(self, duration_s: float) -> None:
        """Bring the turn to rest within ``duration_s`` C2-continuously (on the same axis, a little further on)."""
        s = self._s
        p, v, a = s.position.copy(), s.velocity.copy(), s.acceleration.copy()
        goal = np.clip(p + 0.5 * v * duration_s, 0.0, 1.0)
        self._s = Quintic((p, v, a), (goal, np.zeros(1), np.zeros(1)), duration_s)

    def update(self, dt_s: float) -> None:
        self._s.update(dt_s)
        s, ds, dds = float(self._s.position[0]), float(self._s.velocity[0]), float(self._s.acceleration[0])
        s = min(max(s, 0.0), 1.0)
        self.R[:] = self.R0 @ pin.exp3(s * self.theta)
        # the axis is fixed, so body and world angular rates differ only by R0
        self.omega[:] = self.R0 @ (ds * self.theta)
        self.domega[:] = self.R0 @ (dds * self.theta)


def orientation_duration(R0: np.ndarray, R1: np.ndarray, mean_rate_rad_s: float, about_z: float = 0.0) -> float:
    """Time [s] to turn from R0 to R1 at a mean angular speed (``about_z``: as :class:`OrientationBlend`)."""
    return float(np.linalg.norm(turn_vector(R0, R1, about_z))) / mean_rate_rad_s


# compiled (or loaded from numba's cache) on import, for the arrays a Quintic makes: the first free motion starts
# inside a control tick, which must not wait for the compiler
Quintic((np.zeros(3),) * 3, (np.ones(3), np.zeros(3), np.zeros(3)), 1.0).update(0.5)
