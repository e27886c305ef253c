"""Baselines for the paper's Fig. 6, sampled like :func:`transitional.rollout`.

* :class:`TargetCrossingDMP`: a second-order DMP whose goal moves so that it
  crosses the next MP's entry position with the entry velocity at ``t = T``
  (the joining scheme of Kulvicius et al., "Joining movement sequences:
  modified dynamic movement primitives for robotics applications exemplified
  on handwriting", IEEE T-RO 2012, which the paper cites as target crossing).
  It is the second-order analogue of :mod:`transitional` (same phase,
  basis, normalised time and window), without the acceleration state:

      tau dz = alpha_z (beta_z (g(t) - y) + (tau g'(t) - z)) + tau^2 g''(t) + f(x),   tau dy = z,

  with ``alpha_z = 2 q``, ``beta_z = q / 2`` (critically damped double pole at
  ``q / T``) and ``g(t) = g1 + w(t - T) g2 (t - T)``. Its state is position and
  velocity only, so its acceleration at ``t = 0`` is whatever the dynamics
  give (not ``a0``), and at ``t = T`` it arrives with ``g''(T) = 0``, not ``g3``.
* :func:`ruckig_transition`: a time-synchronised jerk-limited trajectory
  (ruckig, offline ``calculate`` + ``at_time``) between the same full states
  in the same time, with limits derived from the states
  (:func:`limits_from_states`: a margin over the peaks of the quintic that
  joins them in that time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lampskit.core.transitional import (
    DEFAULT_LAMBDA,
    DEFAULT_N_BASIS,
    DEFAULT_REACH_M,
    MIN_DURATION_S,
    MIN_SAMPLES,
    TrajectorySamples,
)
from lampskit.core.transitional_maths import (
    basis_centres_widths,
    crossing_target_coefficients,
    crossing_window_s,
    forcing_term,
    phase,
)
from lampskit.errors import LearningError, PlanningError
from lampskit.learn.derivatives import resample_uniform
from lampskit.learn.transitional_fit import smooth_kinematics

#: Pole of the second-order baseline (per duration), as the third-order MP's ``p``.
DEFAULT_Q = 20.0


@dataclass(frozen=True, eq=False)
class TargetCrossingDMP:
    """A learned second-order target-crossing DMP.

    Attributes
    ----------
    weights : array, shape (N, n_dims)
        Forcing weights (normalised acceleration units).
    centres, widths : arrays, shape (N,)
    q : float
        Double pole at ``q / T``.
    lambda_ : float
        Phase decay, ``x = exp(-lambda t / T)``.
    crossing_reach_m : float
        Window of the moving goal, as :func:`transitional.crossing_window_s`.
    demo_duration_s : float
    demo_start, demo_goal : arrays, shape (2, n_dims)
        Position [m] and velocity [m/s] at both ends of the demonstration.
    """

    weights: np.ndarray
    centres: np.ndarray
    widths: np.ndarray
    q: float
    lambda_: float
    crossing_reach_m: float
    demo_duration_s: float
    demo_start: np.ndarray
    demo_goal: np.ndarray

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=float)
        if w.ndim != 2 or not np.all(np.isfinite(w)):
            raise LearningError(f"TargetCrossingDMP.weights must be a finite (N, n) array, got shape {w.shape}")
        if not (1.0 <= self.q <= 60.0 and 0.1 <= self.lambda_ <= 30.0 and self.demo_duration_s > 0):
            raise LearningError("TargetCrossingDMP: need q in [1, 60], lambda_ in [0.1, 30], duration > 0")


def learn_target_crossing_dmp(
    t_s: np.ndarray,
    y: np.ndarray,
    *,
    n_basis: int = DEFAULT_N_BASIS,
    q: float = DEFAULT_Q,
    lambda_: float = DEFAULT_LAMBDA,
    crossing_reach_m: float = DEFAULT_REACH_M,
    smoothing_window_s: float = 0.08,
) -> TargetCrossingDMP:
    """Learn the second-order baseline from the same segment as the transitional MP.

    Position, velocity and acceleration come from one least-squares quintic
    spline (:func:`transitional.smooth_kinematics`, consistent derivatives);
    the forcing target ``f = dE2/ds + q^2 e1 + 2 q e2`` (``e = Y - G``,
    normalised) is fitted by least squares on the normalised basis.

    Parameters
    ----------
    t_s : array, shape (T,)
        Sample times [s].
    y : array, shape (T, n_dims)
        Positions [m].

    Raises
    ------
    LearningError
        Too short, non-finite or non-increasing samples.
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float)
    y = y[:, None] if y.ndim == 1 else y
    if y.ndim != 2 or len(y) != len(t) or len(t) < MIN_SAMPLES:
        raise LearningError(f"segment must have >= {MIN_SAMPLES} samples of shape (n_dims,), got {y.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y)) and np.all(np.diff(t) > 0)):
        raise LearningError("segment must be finite with strictly increasing timestamps")
    if t[-1] - t[0] < MIN_DURATION_S:
        raise LearningError(f"segment too short: {t[-1] - t[0]:.3f} s, need at least {MIN_DURATION_S} s")
    tu, yu = resample_uniform(t, y)
    T = float(tu[-1] - tu[0])
    pos, vel, acc, _ = smooth_kinematics(tu - tu[0], yu, smoothing_window_s)
    start, goal = np.stack([pos[0], vel[0]]), np.stack([pos[-1], vel[-1]])
    s = (tu - tu[0]) / T
    sigma = crossing_window_s(np.vstack([goal, 0.0 * goal[:1]]), T, crossing_reach_m)
    g = crossing_target_coefficients(tu - tu[-1], sigma)[:, :3, :2] @ goal  # (m, 3, n)
    e1, e2, de2 = pos - g[:, 0], T * (vel - g[:, 1]), T * T * (acc - g[:, 2])
    f_target = de2 + q * q * e1 + 2.0 * q * e2
    centres, widths = basis_centres_widths(n_basis, lambda_)
    x = np.asarray(phase(s, lambda_))
    psi = np.exp(-widths * (x[:, None] - centres) ** 2)
    design = psi / psi.sum(axis=1, keepdims=True) * x[:, None]
    gram = design.T @ design
    gram[np.diag_indices_from(gram)] += 1e-9 * np.trace(gram) / n_basis
    weights = np.linalg.solve(gram, design.T @ f_target)
    return TargetCrossingDMP(
        weights, centres, widths, float(q), float(lambda_), float(crossing_reach_m), T, start, goal
    )


def rollout_target_crossing_dmp(
    mp: TargetCrossingDMP,
    start: object,
    goal: object,
    duration_s: float,
    *,
    dt_s: float = 0.001,
    forcing_transform: np.ndarray | None = None,
) -> TrajectorySamples:
    """Integrate the baseline from ``(y0, v0)`` to ``(g1, g2)`` in ``duration_s``.

    Parameters
    ----------
    start : (y0, v0[, a0]), arrays of shape (n_dims,)
        Only position and velocity are used: a second-order system has no
        acceleration state (its acceleration at t = 0 is computed, not set).
    goal : (g1, g2[, g3]), arrays of shape (n_dims,)
        ``g3`` is ignored.
    dt_s : float
        Output and integration step [s] (RK4 in normalised time, forcing at
        the half steps).
    forcing_transform : array, shape (n_dims, n_dims), optional

    Returns
    -------
    TrajectorySamples
        Every ``dt_s`` from 0 to the first sample at or after ``T``;
        accelerations are the right-hand side of the dynamics.
    """
    n = mp.weights.shape[1]
    st, gl = _two_rows("start", start, n), _two_rows("goal", goal, n)
    T = float(duration_s)
    if not (math.isfinite(T) and T > 0 and math.isfinite(dt_s) and dt_s > 0):
        raise PlanningError(f"need finite duration_s > 0 and dt_s > 0, got {duration_s!r}, {dt_s!r}")
    M = np.eye(n) if forcing_transform is None else np.asarray(forcing_transform, dtype=float)
    if M.shape != (n, n):
        raise PlanningError(f"forcing_transform must have shape ({n}, {n}), got {M.shape}")
    k = int(math.ceil(T / dt_s - 1e-9))
    t = np.arange(k + 1) * dt_s
    h = dt_s / T
    s_half = np.arange(2 * k + 1) * (0.5 * h)
    f = forcing_term(np.asarray(phase(s_half, mp.lambda_)), mp.weights, mp.centres, mp.widths) @ M.T  # (2k+1, n)
    sigma = crossing_window_s(np.vstack([gl, 0.0 * gl[:1]]), T, mp.crossing_reach_m)
    g = crossing_target_coefficients(s_half * T - T, sigma)[:, :3, :2] @ gl  # (2k+1, 3, n)
    q = mp.q

    def accel_norm(j: int, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """dz/ds at half-step index j (normalised)."""
        e1, e2 = y - g[j, 0], z - T * g[j, 1]
        return -(q * q * e1 + 2.0 * q * e2) + f[j] + T * T * g[j, 2]

    pos, vel, acc = np.empty((k + 1, n)), np.empty((k + 1, n)), np.empty((k + 1, n))
    y, z = st[0].copy(), T * st[1]
    for i in range(k + 1):
        pos[i], vel[i] = y, z / T
        acc[i] = accel_norm(2 * i, y, z) / (T * T)
        if i == k:
            break
        j = 2 * i
        k1y, k1z = z, accel_norm(j, y, z)
        k2y, k2z = z + 0.5 * h * k1z, accel_norm(j + 1, y + 0.5 * h * k1y, z + 0.5 * h * k1z)
        k3y, k3z = z + 0.5 * h * k2z, accel_norm(j + 1, y + 0.5 * h * k2y, z + 0.5 * h * k2z)
        k4y, k4z = z + h * k3z, accel_norm(j + 2, y + h * k3y, z + h * k3z)
        y = y + (h / 6.0) * (k1y + 2 * k2y + 2 * k3y + k4y)
        z = z + (h / 6.0) * (k1z + 2 * k2z + 2 * k3z + k4z)
    return TrajectorySamples(t, pos, vel, acc)


def _two_rows(name: str, value: object, n: int) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.ndim != 2 or a.shape[0] not in (2, 3) or a.shape[1] != n or not np.all(np.isfinite(a)):
        raise PlanningError(f"{name} must be finite (position, velocity[, acceleration]) of shape ({n},) each")
    return a[:2]


# --------------------------------------------------------------------------
# ruckig


@dataclass(frozen=True)
class KinematicLimits:
    """Per-axis limits for ruckig (symmetric).

    Attributes
    ----------
    max_velocity_m_s, max_acceleration_m_s2, max_jerk_m_s3 : arrays, shape (n_dims,)
        All > 0.
    """

    max_velocity_m_s: np.ndarray
    max_acceleration_m_s2: np.ndarray
    max_jerk_m_s3: np.ndarray

    def __post_init__(self) -> None:
        for name in ("max_velocity_m_s", "max_acceleration_m_s2", "max_jerk_m_s3"):
            a = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if not (np.all(np.isfinite(a)) and np.all(a > 0)):
                raise PlanningError(f"KinematicLimits.{name} must be finite and > 0, got {a.tolist()}")
            object.__setattr__(self, name, a)


def limits_from_states(start: np.ndarray, goal: np.ndarray, duration_s: float, margin: float = 1.2) -> KinematicLimits:
    """Limits under which ruckig can join ``start`` to ``goal`` in exactly ``duration_s``.

    Per axis, ``margin`` times the peaks of the quintic (minimum-jerk)
    polynomial that joins the same full states in the same time; that
    polynomial proves a trajectory of duration ``T`` exists within them, so
    with ``minimum_duration = T`` ruckig ends at ``T``. The jerk limit is
    raised, if needed, so that both boundary accelerations can be removed
    within the velocity limit (ruckig rejects a state with
    ``|v| + a^2 / (2 j) > v_max``).

    Parameters
    ----------
    start, goal : arrays, shape (3, n_dims)
        ``(y, v, a)`` at both ends [m, m/s, m/s^2].
    duration_s : float
        ``T`` [s].
    margin : float
        Factor (> 1) on the quintic's peaks.
    """
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    T = float(duration_s)
    _, vel, acc, jerk = _quintic(start, goal, T, np.linspace(0.0, T, 401))
    tiny = np.full(start.shape[1], 1e-6)
    v = margin * np.maximum(np.abs(vel).max(axis=0), tiny)
    a = margin * np.maximum(np.abs(acc).max(axis=0), tiny)
    j_reach = np.maximum(start[2] ** 2 / (2 * (v - np.abs(start[1]))), goal[2] ** 2 / (2 * (v - np.abs(goal[1]))))
    j = np.maximum(margin * np.maximum(np.abs(jerk).max(axis=0), tiny), margin * j_reach)
    return KinematicLimits(v, a, j)


def _quintic(start: np.ndarray, goal: np.ndarray, T: float, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """The quintic joining two full states in ``T``: position..jerk at ``t``, each shape (m, n_dims)."""
    # coefficients of y(t) = sum_k c_k t^k, k = 0..5, from the six boundary conditions
    A = np.array([[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 2, 0, 0, 0],
                  [1, T, T**2, T**3, T**4, T**5], [0, 1, 2 * T, 3 * T**2, 4 * T**3, 5 * T**4],
                  [0, 0, 2, 6 * T, 12 * T**2, 20 * T**3]], dtype=float)
    c = np.linalg.solve(A, np.vstack([start, goal]))  # (6, n)
    powers = t[:, None] ** np.arange(6)
    out = []
    for d in range(4):
        k = np.arange(d, 6)
        fall = np.prod([k - i for i in range(d)], axis=0) if d else np.ones(len(k))
        out.append((powers[:, : 6 - d] * fall) @ c[d:])
    return tuple(out)


def ruckig_transition(
    start: object,
    goal: object,
    duration_s: float,
    *,
    dt_s: float = 0.001,
    limits: KinematicLimits | None = None,
) -> TrajectorySamples:
    """A jerk-limited trajectory from ``start`` to ``goal`` (full states), at least ``duration_s`` long.

    Uses ruckig offline (``Ruckig.calculate`` into a ``Trajectory``, then
    ``at_time``) with ``minimum_duration = duration_s`` and time
    synchronisation, so with the default :func:`limits_from_states` all axes
    end together at ``T``; tighter limits may make it longer.

    Parameters
    ----------
    start, goal : (y, v, a), arrays of shape (n_dims,)
        [m, m/s, m/s^2].
    duration_s : float
        Minimum duration ``T`` [s].
    dt_s : float
        Sample step [s].
    limits : KinematicLimits, optional
        Default :func:`limits_from_states`.

    Returns
    -------
    TrajectorySamples
        Every ``dt_s`` from 0 to the first sample at or after the trajectory's
        duration (beyond it: constant-acceleration extrapolation of the target).

    Raises
    ------
    PlanningError
        Bad inputs, or ruckig cannot reach the target state under the limits
        (the message carries ruckig's reason).
    """
    from ruckig import InputParameter, Result, Ruckig, RuckigError, Trajectory

    st, gl = np.array(start, dtype=float), np.array(goal, dtype=float)
    finite = np.all(np.isfinite(st)) and np.all(np.isfinite(gl))
    if st.ndim != 2 or st.shape[0] != 3 or gl.shape != st.shape or not finite:
        raise PlanningError(f"start and goal must be finite (y, v, a) of equal shape (n,), got {st.shape}, {gl.shape}")
    if not (math.isfinite(duration_s) and duration_s > 0 and math.isfinite(dt_s) and dt_s > 0):
        raise PlanningError(f"need finite duration_s > 0 and dt_s > 0, got {duration_s!r}, {dt_s!r}")
    n = st.shape[1]
    lim = limits or limits_from_states(st, gl, duration_s)
    inp = InputParameter(n)
    inp.current_position, inp.current_velocity, inp.current_acceleration = (r.tolist() for r in st)
    inp.target_position, inp.target_velocity, inp.target_acceleration = (r.tolist() for r in gl)
    inp.max_velocity = lim.max_velocity_m_s.tolist()
    inp.max_acceleration = lim.max_acceleration_m_s2.tolist()
    inp.max_jerk = lim.max_jerk_m_s3.tolist()
    inp.minimum_duration = float(duration_s)
    trajectory = Trajectory(n)
    try:
        result = Ruckig(n).calculate(inp, trajectory)
    except RuckigError as exc:
        raise PlanningError(f"ruckig cannot reach the target state: {str(exc).strip()}") from None
    if result not in (Result.Working, Result.Finished):
        raise PlanningError(f"ruckig cannot reach the target state: {result!r}")
    duration = trajectory.duration
    k = int(math.ceil(duration / dt_s - 1e-9))
    t = np.arange(k + 1) * dt_s
    out = np.array([trajectory.at_time(float(ti)) for ti in np.minimum(t, duration)])  # (m, 3, n)
    # past the end: the target's constant-acceleration extrapolation, as the transitional runner
    u = np.maximum(t - duration, 0.0)[:, None]
    pos = out[:, 0] + u * out[:, 1] + 0.5 * u * u * out[:, 2]
    return TrajectorySamples(t, pos, out[:, 1] + u * out[:, 2], out[:, 2])
