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
from lampskit.core.periodic_forcing import ForcingEvaluator
from lampskit.core.periodic_ramp import ParameterRamp
from lampskit.core.periodic_step import StepMaps
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
        ramp = self._ramp
        self._forcing.into(self.phase_rad, self._z[2], ramp.S if ramp.has_stroke else None)
        self._write_outputs(self._z)

    def _allocate(self, mp: PeriodicMP, anchor: np.ndarray, amp: float, omega: float, tau: float,
                  pos0: np.ndarray, vel0: np.ndarray, stroke: np.ndarray | None) -> None:
        """Every buffer the step uses, allocated once; the state set to ``pos0``, ``vel0`` (n_dims,)."""
        n = mp.n_dims
        self.mp = mp
        self.n_dims = n
        self._forcing = ForcingEvaluator(mp)
        self._ramp = ParameterRamp(anchor, amp, omega, stroke, tau)
        self._maps = StepMaps(mp.alpha, mp.beta)
        # State, double-buffered, rows: x1 = y1 - y_m, x2 = y2, F(phi) (r = 1), dF over the step.
        self._z = np.zeros((4, n))
        self._z_next = np.zeros((4, n))
        self._z[0] = pos0 - anchor
        self._z[1] = vel0 / omega
        # Outputs, rows: position [m], velocity [m/s], acceleration [m/s^2].
        self._out = np.empty((3, n))
        self.position_m = self._out[0]
        self.velocity_m_s = self._out[1]
        self.acceleration_m_s2 = self._out[2]

    # -- effective parameters (read only)
    @property
    def anchor_m(self) -> np.ndarray:
        """Effective y_m [m], shape (n_dims,) (a copy)."""
        return self._ramp.ym.copy()

    @property
    def amplitude_m(self) -> float:
        """Effective r [m]."""
        return self._ramp.r

    @property
    def omega_rad_s(self) -> float:
        """Effective Omega [rad/s]."""
        return self._ramp.omega

    @property
    def stroke(self) -> np.ndarray:
        """Effective stroke S, shape (n_dims, n_dims) (a copy; the identity when none was given)."""
        return self._ramp.S.copy()

    @property
    def is_ramping(self) -> bool:
        """True while y_m, r, Omega or the stroke still move toward their targets."""
        return self._ramp.ramping

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
        anchor = None if anchor_m is None else np.asarray(anchor_m, dtype=float)
        if anchor is not None and (anchor.shape != (self.n_dims,) or not np.isfinite(anchor).all()):
            return PeriodicStatus.ERROR_INVALID_INPUT
        for value in (amplitude_m, omega_rad_s):
            if value is not None and not (math.isfinite(value) and value > 0):
                return PeriodicStatus.ERROR_INVALID_INPUT
        if stroke is not None:
            try:
                stroke = check_stroke(stroke, self.n_dims)
            except PlanningError:
                return PeriodicStatus.ERROR_INVALID_INPUT
        self._ramp.retarget(anchor, amplitude_m, omega_rad_s, stroke, self._z[0])
        return PeriodicStatus.WORKING

    def update(self, dt_s: float) -> PeriodicStatus:
        """Advance eqs. (1)-(3) by ``dt_s`` (0 < dt_s <= MAX_DT_S) and refresh the outputs."""
        t0 = time.perf_counter_ns()
        if not 0.0 < dt_s <= MAX_DT_S:
            return PeriodicStatus.ERROR_INVALID_INPUT
        ramp, maps = self._ramp, self._maps
        if ramp.ramping:
            ramp.advance(dt_s, self._z[0])
        a = ramp.omega * dt_s
        r = ramp.r
        if a != maps.step_key[0] or r != maps.step_key[1]:
            maps.rebuild_step(a, r)
        phase = self.phase_rad + a
        if phase >= TWO_PI:
            wraps = int(phase // TWO_PI)
            phase -= wraps * TWO_PI
            self.cycles += wraps
        self.phase_rad = phase
        z, z_next = self._z, self._z_next
        self._forcing.into(phase, z_next[2], ramp.S if ramp.has_stroke else None)
        np.subtract(z_next[2], z[2], out=z[3])
        np.matmul(maps.step, z, out=z_next[:2])
        self._z, self._z_next = z_next, z
        self._write_outputs(z_next)
        self.time_s += dt_s
        self.calculation_duration_us = (time.perf_counter_ns() - t0) * 1e-3
        return PeriodicStatus.WORKING

    def _write_outputs(self, z: np.ndarray) -> None:
        """[pos - y_m, vel, acc] = [[1, 0, 0], [0, W, 0], [-ab W^2, -a W^2, r W^2]] @ (x1, x2, F)."""
        ramp, maps = self._ramp, self._maps
        om, r = ramp.omega, ramp.r
        if om != maps.out_key[0] or r != maps.out_key[1]:
            maps.rebuild_out(om, r)
        np.matmul(maps.out, z[:3], out=self._out)
        self.position_m += ramp.ym


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
