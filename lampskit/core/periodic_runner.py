"""Step API of the periodic DMP: :class:`PeriodicRunner`, ruckig style.

Exponential integrator: over one step of length dt the phase advances by
``a = Omega dt`` and ``x = (y1 - y_m, y2)`` obeys ``dx/da = M x + e2 r F``
with ``M = [[0, 1], [-alpha beta, -alpha]]``. The homogeneous part is
propagated exactly (``exp(M a)`` in closed form), the forcing with a
first-order hold (linear in phase across the step). This is unconditionally
stable for every Omega and dt (the DMP poles sit at ``-alpha Omega / 2``,
e.g. -236 rad/s at 3 Hz), second-order accurate in the forcing, and needs
one basis evaluation (N exps) per step, unlike RK4 (three). Changes of
``y_m``, ``r`` and ``Omega`` go through critically damped second-order
filters (time constant :data:`DEFAULT_RAMP_TIME_CONSTANT_S`), so the
effective parameters are C1 and the output position, velocity and
acceleration stay continuous.
"""

from __future__ import annotations

import math
import time
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from lampskit.core.periodic import TWO_PI, PeriodicMP, check_execution_params, check_stroke, periodic_state_unchecked
from lampskit.errors import PlanningError

#: Default time constant tau of the critically damped parameter filters [s]: a step
#: in a target is 90 % done after 3.9 tau (0.78 s), with no overshoot.
DEFAULT_RAMP_TIME_CONSTANT_S = 0.2
#: update() rejects steps longer than this [s].
MAX_DT_S = 0.1

class PeriodicStatus(IntEnum):
    """Result of :meth:`PeriodicRunner.update` (ruckig style: negative = error)."""

    WORKING = 0
    ERROR_INVALID_INPUT = -100


def step_matrix(phase_step_rad: float, alpha: float, beta: float) -> np.ndarray:
    """Exact one-step map of eqs. (1)-(2) for a phase step ``a = Omega dt``.

    With ``x = (y1 - y_m, y2)`` per dimension, ``u0 = r F(phi_k)`` and
    ``du = r (F(phi_k+1) - F(phi_k))`` (forcing linear in phase over the step)::

        x_k+1 = Phi x_k + g0 u0 + g1 du,
        Phi = exp(M a),  g0 = M^-1 (Phi - I) e2,  g1 = (M^-1 g0 - a M^-1 e2) / a,
        M = [[0, 1], [-alpha beta, -alpha]].

    Parameters
    ----------
    phase_step_rad : float
        a = Omega dt > 0 [rad].
    alpha, beta : float

    Returns
    -------
    mat : array, shape (2, 4)
        ``[Phi | g0 | g1]``, to multiply ``(x1, x2, u0, du)`` stacked as rows (4, n).
    """
    return np.array(_step_coefficients(phase_step_rad, alpha, beta)).reshape(2, 4)


def _step_coefficients(a: float, alpha: float, beta: float) -> tuple[float, ...]:
    """Entries of :func:`step_matrix`, row-major, as Python floats (no allocation of arrays)."""
    k, c = alpha * beta, alpha
    mu = -0.5 * c
    disc = 0.25 * c * c - k
    z = disc * a * a
    if abs(z) < 1e-6:
        cc = 1.0 + z / 2.0 + z * z / 24.0
        ss = a * (1.0 + z / 6.0 + z * z / 120.0)
    elif disc > 0:
        q = math.sqrt(disc)
        cc, ss = math.cosh(q * a), math.sinh(q * a) / q
    else:
        q = math.sqrt(-disc)
        cc, ss = math.cos(q * a), math.sin(q * a) / q
    e = math.exp(mu * a)
    p11 = e * (cc - mu * ss)
    p12 = e * ss
    p21 = -k * e * ss
    p22 = e * (cc - mu * ss - c * ss)
    g0_1 = (-c * p12 - (p22 - 1.0)) / k
    g0_2 = p12
    g1_1 = (a - c * g0_1 - g0_2) / (k * a)
    g1_2 = g0_1 / a
    return p11, p12, g0_1, g1_1, p21, p22, g0_2, g1_2


def _start_state(mp: PeriodicMP, phase: float, anchor: np.ndarray, amp: float, omega: float,
                 start_position_m, start_velocity_m_s, stroke=None) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity (n_dims,) to start from: the limit cycle's at ``phase`` unless given (checked)."""
    n = mp.n_dims
    pos0, vel0, _ = periodic_state_unchecked(mp.limit_cycle, np.asarray(phase % TWO_PI), anchor, amp, omega,
                                             stroke)
    for name, value in (("start_position_m", start_position_m), ("start_velocity_m_s", start_velocity_m_s)):
        if value is not None and (np.shape(value) != (n,) or not np.isfinite(value).all()):
            raise PlanningError(f"{name} must be a finite array of shape ({n},), got {value!r}")
    if start_position_m is not None:
        pos0 = np.asarray(start_position_m, dtype=float)
    if start_velocity_m_s is not None:
        vel0 = np.asarray(start_velocity_m_s, dtype=float)
    return pos0, vel0


class PeriodicRunner:
    """Runs a periodic DMP at a fixed control rate, ruckig style.

    Build once, then call :meth:`update` every cycle; read
    :attr:`position_m`, :attr:`velocity_m_s`, :attr:`acceleration_m_s2`
    (arrays of shape (n_dims,), overwritten in place: copy to keep) and
    :attr:`phase_rad`. :meth:`set_targets` moves y_m, r, Omega and the
    stroke to new values through critically damped filters of time constant
    ``ramp_time_constant_s`` (0 = jump at once).

    The *stroke* S (n_dims, n_dims) maps the learned cycle about y_m
    (stretch and turn it, :func:`~lampskit.core.periodic.stroke_matrix`):
    the forcing is ``r S F(phi)``, so with S constant the limit cycle is
    ``y_m + r S s(phi)``; a changing S goes through the same filters, and
    position, velocity and acceleration stay continuous.

    Parameters
    ----------
    mp : PeriodicMP
    anchor_m : array, shape (n_dims,), optional
        y_m [m]; default ``mp.anchor_m``.
    amplitude_m : float, optional
        r [m]; default ``mp.amplitude_m``.
    omega_rad_s : float, optional
        Omega [rad/s]; default ``mp.omega_rad_s``.
    start_phase_rad : float, optional
        Initial phase [rad]; default ``mp.phase_start_rad``.
    start_position_m, start_velocity_m_s : arrays, shape (n_dims,), optional
        Initial state [m], [m/s]; each defaults to the limit cycle at the start phase.
    ramp_time_constant_s : float
        Time constant of the parameter filters [s], >= 0.
    stroke : array, shape (n_dims, n_dims), optional
        Initial stroke; default none (the identity, and no extra work per step until :meth:`set_targets` gives one).

    Attributes
    ----------
    position_m, velocity_m_s, acceleration_m_s2 : arrays, shape (n_dims,)
        State after the last update [m], [m/s], [m/s^2] (views, overwritten in place).
    phase_rad : float
        Phase in [0, 2 pi) [rad]; ``cycles`` counts the wraps and
        ``phase_unwrapped_rad`` = cycles * 2 pi + phase_rad.
    time_s : float
        Time integrated since construction [s].
    calculation_duration_us : float
        Wall time of the last update [us].

    Raises
    ------
    PlanningError
        Invalid execution parameters (at construction only).
    """

    def __init__(
        self,
        mp: PeriodicMP,
        anchor_m: np.ndarray | None = None,
        amplitude_m: float | None = None,
        omega_rad_s: float | None = None,
        start_phase_rad: float | None = None,
        *,
        start_position_m: np.ndarray | None = None,
        start_velocity_m_s: np.ndarray | None = None,
        ramp_time_constant_s: float = DEFAULT_RAMP_TIME_CONSTANT_S,
        stroke: np.ndarray | None = None,
    ) -> None:
        anchor, amp, omega = check_execution_params(mp, anchor_m, amplitude_m, omega_rad_s)
        if stroke is not None:
            stroke = check_stroke(stroke, mp.n_dims)
        phase = mp.phase_start_rad if start_phase_rad is None else float(start_phase_rad)
        if not math.isfinite(phase):
            raise PlanningError(f"start_phase_rad must be finite, got {start_phase_rad!r}")
        tau = float(ramp_time_constant_s)
        if not (math.isfinite(tau) and tau >= 0):
            raise PlanningError(f"ramp_time_constant_s must be finite and >= 0 s, got {ramp_time_constant_s!r}")
        pos0, vel0 = _start_state(mp, phase, anchor, amp, omega, start_position_m, start_velocity_m_s, stroke)
        self._allocate(mp, anchor, amp, omega, tau, pos0, vel0, stroke)
        self.phase_rad = phase % TWO_PI
        self.cycles = int(phase // TWO_PI)
        self.time_s = 0.0
        self.calculation_duration_us = 0.0
        self._forcing_into(self.phase_rad, self._z[2])
        self._write_outputs(self._z)

    def _allocate(self, mp: PeriodicMP, anchor: np.ndarray, amp: float, omega: float, tau: float,
                  pos0: np.ndarray, vel0: np.ndarray, stroke: np.ndarray | None) -> None:
        """Every buffer the step uses, allocated once; the state set to ``pos0``, ``vel0`` (n_dims,)."""
        n = mp.n_dims
        self.mp = mp
        self.n_dims = n
        self._alpha, self._beta = mp.alpha, mp.beta
        # Forcing, eq. (4): [cos phi, sin phi, 1] @ H = h (cos(phi - c) - 1), then
        # exp, then psi @ [W | 1] gives numerator and denominator in one product.
        self._cs = np.array([0.0, 0.0, 1.0])
        self._h3 = np.ascontiguousarray(
            np.stack([mp.widths * np.cos(mp.centres_rad), mp.widths * np.sin(mp.centres_rad), -mp.widths])
        )
        self._w1 = np.ascontiguousarray(np.column_stack([mp.weights, np.ones(mp.n_basis)]))
        self._psi = np.empty(mp.n_basis)
        self._num = np.empty(n + 1)
        self._omega_f = 0.0 if tau == 0 else 1.0 / tau
        # Effective parameters and their filters. Columns: y_m (n), r, Omega, the stroke's entries (n n, row-major);
        # targets (n + 2 + n n,); filter state rows: error (value - target), rate.
        self._ym = anchor.copy()
        self._r, self._omega = amp, omega
        self._has_stroke = stroke is not None  # without one the step skips the map (bit for bit as before strokes)
        self._S = np.eye(n) if stroke is None else stroke.copy()
        self._S_flat = self._S.reshape(-1)  # a view
        self._f_raw = np.empty(n)
        self._targets = np.concatenate([anchor, [amp, omega], self._S_flat])
        self._ev = np.zeros((2, n + 2 + n * n))
        self._ev_next = np.zeros((2, n + 2 + n * n))
        self._filter_map = np.empty((2, 2))
        self._filter_dt = math.nan
        self._delta = np.empty(n)
        self._settle_countdown = 0
        self._ramping = False
        # State, double-buffered, rows: x1 = y1 - y_m, x2 = y2, F(phi) (r = 1), dF over the step.
        self._z = np.zeros((4, n))
        self._z_next = np.zeros((4, n))
        self._z[0] = pos0 - anchor
        self._z[1] = vel0 / omega
        # Step map [Phi | r g0 | r g1] (2, 4) and output map (3, 3), rebuilt when a, r or Omega change.
        self._step = np.empty((2, 4))
        self._step_key = (math.nan, math.nan)
        self._out_map = np.zeros((3, 3))
        self._out_map[0, 0] = 1.0
        self._out_key = (math.nan, math.nan)
        # Outputs, rows: position [m], velocity [m/s], acceleration [m/s^2].
        self._out = np.empty((3, n))
        self.position_m = self._out[0]
        self.velocity_m_s = self._out[1]
        self.acceleration_m_s2 = self._out[2]

    # -- effective parameters (read only)
    @property
    def anchor_m(self) -> np.ndarray:
        """Effective y_m [m], shape (n_dims,) (a copy)."""
        return self._ym.copy()

    @property
    def amplitude_m(self) -> float:
        """Effective r [m]."""
        return self._r

    @property
    def omega_rad_s(self) -> float:
        """Effective Omega [rad/s]."""
        return self._omega

    @property
    def stroke(self) -> np.ndarray:
        """Effective stroke S, shape (n_dims, n_dims) (a copy; the identity when none was given)."""
        return self._S.copy()

    @property
    def is_ramping(self) -> bool:
        """True while y_m, r, Omega or the stroke still move toward their targets."""
        return self._ramping

    @property
    def phase_unwrapped_rad(self) -> float:
        """Phase since the start, not wrapped [rad]."""
        return self.cycles * TWO_PI + self.phase_rad

    def set_targets(
        self, *, anchor_m: np.ndarray | None = None, amplitude_m: float | None = None,
        omega_rad_s: float | None = None, stroke: np.ndarray | None = None,
    ) -> PeriodicStatus:
        """New targets for y_m [m] (n_dims,), r [m], Omega [rad/s], the stroke (n_dims, n_dims); None keeps a target.

        Returns ERROR_INVALID_INPUT (and changes nothing) for a wrong shape,
        a non-finite value, a non-positive amplitude / frequency or a stroke
        outside :func:`~lampskit.core.periodic.check_stroke`.
        """
        if anchor_m is not None:
            anchor = np.asarray(anchor_m, dtype=float)
            if anchor.shape != (self.n_dims,) or not np.isfinite(anchor).all():
                return PeriodicStatus.ERROR_INVALID_INPUT
        for value in (amplitude_m, omega_rad_s):
            if value is not None and not (math.isfinite(value) and value > 0):
                return PeriodicStatus.ERROR_INVALID_INPUT
        if stroke is not None:
            try:
                stroke = check_stroke(stroke, self.n_dims)
            except PlanningError:
                return PeriodicStatus.ERROR_INVALID_INPUT
        n, targets = self.n_dims, self._targets
        if anchor_m is not None:
            targets[:n] = anchor
        if amplitude_m is not None:
            targets[n] = float(amplitude_m)
        if omega_rad_s is not None:
            targets[n + 1] = float(omega_rad_s)
        if stroke is not None:
            targets[n + 2:] = stroke.reshape(-1)
            self._has_stroke = True
        if self._omega_f == 0.0:  # no ramp: jump now
            self._snap_to_targets()
        else:
            self._ev[0, :n] = self._ym - targets[:n]
            self._ev[0, n] = self._r - targets[n]
            self._ev[0, n + 1] = self._omega - targets[n + 1]
            np.subtract(self._S_flat, targets[n + 2:], out=self._ev[0, n + 2:])
            self._ramping = True
        return PeriodicStatus.WORKING

    def update(self, dt_s: float) -> PeriodicStatus:
        """Advance eqs. (1)-(3) by ``dt_s`` (0 < dt_s <= MAX_DT_S) and refresh the outputs."""
        t0 = time.perf_counter_ns()
        if not 0.0 < dt_s <= MAX_DT_S:
            return PeriodicStatus.ERROR_INVALID_INPUT
        if self._ramping:
            self._advance_filters(dt_s)
        a = self._omega * dt_s
        r = self._r
        if a != self._step_key[0] or r != self._step_key[1]:
            p11, p12, g01, g11, p21, p22, g02, g12 = _step_coefficients(a, self._alpha, self._beta)
            m = self._step
            m[0, 0], m[0, 1], m[0, 2], m[0, 3] = p11, p12, r * g01, r * g11
            m[1, 0], m[1, 1], m[1, 2], m[1, 3] = p21, p22, r * g02, r * g12
            self._step_key = (a, r)
        phase = self.phase_rad + a
        if phase >= TWO_PI:
            wraps = int(phase // TWO_PI)
            phase -= wraps * TWO_PI
            self.cycles += wraps
        self.phase_rad = phase
        z, z_next = self._z, self._z_next
        self._forcing_into(phase, z_next[2])
        np.subtract(z_next[2], z[2], out=z[3])
        np.matmul(self._step, z, out=z_next[:2])
        self._z, self._z_next = z_next, z
        self._write_outputs(z_next)
        self.time_s += dt_s
        self.calculation_duration_us = (time.perf_counter_ns() - t0) * 1e-3
        return PeriodicStatus.WORKING

    def _forcing_into(self, phase: float, out: np.ndarray) -> None:
        """Eq. (4) with r = 1 at ``phase``, mapped by the stroke, into ``out`` (n,), without allocating."""
        cs, psi, num = self._cs, self._psi, self._num
        cs[0] = math.cos(phase)
        cs[1] = math.sin(phase)
        np.dot(cs, self._h3, out=psi)
        np.exp(psi, out=psi)
        np.dot(psi, self._w1, out=num)
        if self._has_stroke:
            np.divide(num[:-1], num[-1], out=self._f_raw)
            np.dot(self._S, self._f_raw, out=out)
        else:
            np.divide(num[:-1], num[-1], out=out)

    def _write_outputs(self, z: np.ndarray) -> None:
        """[pos - y_m, vel, acc] = [[1, 0, 0], [0, W, 0], [-ab W^2, -a W^2, r W^2]] @ (x1, x2, F)."""
        om, r = self._omega, self._r
        if om != self._out_key[0] or r != self._out_key[1]:
            om2, m = om * om, self._out_map
            m[1, 1] = om
            m[2, 0], m[2, 1], m[2, 2] = -self._alpha * self._beta * om2, -self._alpha * om2, r * om2
            self._out_key = (om, r)
        np.matmul(self._out_map, z[:3], out=self._out)
        self.position_m += self._ym

    def _advance_filters(self, dt: float) -> None:
        """Exact step of the critically damped filters e'' = -w^2 e - 2 w e' (e = value - target).

        ``e(t) = (e0 + g t) exp(-w t)``, ``e'(t) = (e0' - w g t) exp(-w t)``, ``g = e0' + w e0``:
        one (2, 2) map applied to every column (y_m per dimension, r, Omega).
        """
        w = self._omega_f
        if dt != self._filter_dt:
            d = math.exp(-w * dt)
            self._filter_map[:] = [[d * (1.0 + w * dt), d * dt], [-d * w * w * dt, d * (1.0 - w * dt)]]
            self._filter_dt = dt
        ev, ev_next, n = self._ev, self._ev_next, self.n_dims
        np.matmul(self._filter_map, ev, out=ev_next)
        # y_m moves by delta; x1 = y1 - y_m shifts so that y1 does not move.
        np.subtract(ev_next[0, :n], ev[0, :n], out=self._delta)
        self._ym += self._delta
        self._z[0] -= self._delta
        self._r = float(self._targets[n] + ev_next[0, n])
        self._omega = float(self._targets[n + 1] + ev_next[0, n + 1])
        if self._has_stroke:
            np.add(self._targets[n + 2:], ev_next[0, n + 2:], out=self._S_flat)
        self._ev, self._ev_next = ev_next, ev
        self._settle_countdown -= 1
        if self._settle_countdown <= 0:
            self._settle_countdown = 32
            scale = self._targets[n]  # amplitude for y_m and r, Omega for Omega
            err = np.abs(ev_next[0]) + np.abs(ev_next[1]) / w
            if err[: n + 1].max() < 1e-9 * scale and err[n + 1] < 1e-9 * self._targets[n + 1] \
                    and err[n + 2:].max() < 1e-9:
                self._snap_to_targets()

    def _snap_to_targets(self) -> None:
        n, targets = self.n_dims, self._targets
        self._z[0] -= targets[:n] - self._ym
        self._ym[:] = targets[:n]
        self._r, self._omega = float(targets[n]), float(targets[n + 1])
        self._S_flat[:] = targets[n + 2:]
        self._ev[:] = 0.0
        self._ramping = False


class Rollout(NamedTuple):
    """Sampled run of a periodic DMP.

    t_s : array, shape (K,) [s]; position_m, velocity_m_s, acceleration_m_s2 :
    arrays, shape (K, n_dims); phase_rad : array, shape (K,), unwrapped [rad].
    """

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray
    phase_rad: np.ndarray


def rollout(mp: PeriodicMP, duration_s: float, dt_s: float = 1e-3, **runner_kwargs) -> Rollout:
    """Integrate eqs. (1)-(3) with :class:`PeriodicRunner` for ``duration_s``.

    Parameters
    ----------
    mp : PeriodicMP
    duration_s : float
        Length [s] (> 0).
    dt_s : float
        Step [s], in (0, MAX_DT_S].
    **runner_kwargs
        Passed to :class:`PeriodicRunner` (anchor_m, amplitude_m, omega_rad_s,
        start_phase_rad, start_position_m, start_velocity_m_s).

    Returns
    -------
    Rollout
        K = round(duration_s / dt_s) + 1 samples, the first being the initial state.
    """
    if not (math.isfinite(duration_s) and duration_s > 0 and 0 < dt_s <= MAX_DT_S):
        raise PlanningError(f"need duration_s > 0 and 0 < dt_s <= {MAX_DT_S}; got {duration_s!r}, {dt_s!r}")
    runner = PeriodicRunner(mp, **runner_kwargs)
    k = int(round(duration_s / dt_s)) + 1
    n = mp.n_dims
    pos, vel, acc = np.empty((k, n)), np.empty((k, n)), np.empty((k, n))
    phase = np.empty(k)
    for i in range(k):
        if i:
            runner.update(dt_s)
        pos[i], vel[i], acc[i] = runner.position_m, runner.velocity_m_s, runner.acceleration_m_s2
        phase[i] = runner.phase_unwrapped_rad
    return Rollout(np.arange(k) * dt_s, pos, vel, acc, phase)
