"""Planning a transition with a learned transitional MP: boundary states in, an exact trajectory out.

:func:`plan_transition` takes the MP, the start state ``(y0, v0, a0)``, the
goal state ``(g1, g2, g3)`` and a duration, and returns a
:class:`TransitionPlan` whose terminal correction makes it land exactly on the
goal; :func:`evaluate` and :func:`rollout` sample it. :func:`similarity_transform`
maps a demonstrated displacement onto a new one (the ``forcing_transform``).
The 1 kHz step API is :mod:`lampskit.core.transitional_runner`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lampskit.core.transitional import TrajectorySamples, TransitionalMP
from lampskit.core.transitional_maths import crossing_target_coefficients, crossing_window_s, hermite_rows
from lampskit.errors import PlanningError

#: Inverse of the position, velocity and acceleration of s^3, s^4, s^5 at s = 1 (terminal correction).
CORRECTION_AT_1_INV = np.linalg.inv(np.array([[1.0, 1.0, 1.0], [3.0, 4.0, 5.0], [6.0, 12.0, 20.0]]))


def similarity_transform(from_vector: np.ndarray, to_vector: np.ndarray) -> np.ndarray:
    """Rotation times uniform scale ``s R`` taking ``from_vector`` onto ``to_vector``.

    A helper for choosing ``forcing_transform``: map the demonstrated
    displacement onto the new one. In 3-D the rotation is the smallest one
    about ``from x to`` (Rodrigues); antiparallel vectors in 3-D turn about
    an axis perpendicular to ``from``.

    Parameters
    ----------
    from_vector, to_vector : arrays, shape (n_dims,)
        Non-zero, n_dims in {1, 2, 3}.

    Returns
    -------
    array, shape (n_dims, n_dims)
    """
    a, b = np.asarray(from_vector, dtype=float), np.asarray(to_vector, dtype=float)
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if a.shape != b.shape or a.ndim != 1 or len(a) not in (1, 2, 3):
        raise PlanningError(f"vectors must share shape (n,) with n in 1..3, got {a.shape} and {b.shape}")
    if not (na > 0.0 and nb > 0.0 and math.isfinite(na) and math.isfinite(nb)):
        raise PlanningError(f"vectors must be finite and non-zero, got norms {na} and {nb}")
    scale = nb / na
    a, b = a / na, b / nb
    if len(a) == 1:
        return np.array([[scale * a[0] * b[0]]])
    if len(a) == 2:
        c, s = a @ b, a[0] * b[1] - a[1] * b[0]
        return scale * np.array([[c, -s], [s, c]])
    axis, cos = np.cross(a, b), float(a @ b)
    sin = float(np.linalg.norm(axis))
    if sin < 1e-12:
        if cos > 0:
            return scale * np.eye(3)
        perp = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        perp /= np.linalg.norm(perp)
        return scale * (2.0 * np.outer(perp, perp) - np.eye(3))
    k = axis / sin
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return scale * (np.eye(3) + sin * kx + (1.0 - cos) * kx @ kx)


@dataclass(frozen=True, eq=False)
class TransitionPlan:
    """One generalised transition, ready to evaluate at any time.

    Built by :func:`plan_transition`; cheap (a few small products, no table work).

    Attributes
    ----------
    mp : TransitionalMP
    start, goal : arrays, shape (3, n_dims)
        ``(y0, v0, a0)`` and ``(g1, g2, g3)`` [m, m/s, m/s^2].
    duration_s : float
        ``T`` [s].
    forcing_transform : array, shape (n_dims, n_dims)
        Matrix applied to the learned forcing term.
    sigma_s : float
        Crossing-target window [s].
    residual : array, shape (3, n_dims)
        ``e(T)`` that the terminal correction cancels [m, m/s, m/s^2] (diagnostic).
    coefficients : array, shape (6 + n_dims, n_dims)
        ``e(s) = table(s) @ coefficients``: rows ``e(0)`` (normalised), the
        transposed forcing transform, and the correction's ``s^3, s^4, s^5`` coefficients.
    """

    mp: TransitionalMP
    start: np.ndarray
    goal: np.ndarray
    duration_s: float
    forcing_transform: np.ndarray
    sigma_s: float
    residual: np.ndarray
    coefficients: np.ndarray


def plan_transition(
    mp: TransitionalMP,
    start: object,
    goal: object,
    duration_s: float,
    forcing_transform: np.ndarray | None = None,
) -> TransitionPlan:
    """Generalise ``mp`` to a new start state, entry state and duration.

    Parameters
    ----------
    start : (y0, v0, a0) or array, shape (3, n_dims)
        State now [m, m/s, m/s^2].
    goal : (g1, g2, g3) or array, shape (3, n_dims)
        Entry state of the next MP [m, m/s, m/s^2].
    duration_s : float
        ``T`` [s], > 0. The learned forcing plays in normalised time, so its
        real jerk scales as ``(T_demo / T)^3`` (velocities ``T_demo / T``).
    forcing_transform : array, shape (n_dims, n_dims), optional
        Applied to the learned forcing term (e.g. ``s R`` from
        :func:`similarity_transform`); default identity, zeros switch it off.

    Raises
    ------
    PlanningError
        Wrong shapes, non-finite values or a non-positive duration.
    """
    n = mp.n_dims
    st, gl = _state_arg("start", start, n), _state_arg("goal", goal, n)
    T = float(duration_s)
    if not (math.isfinite(T) and T > 0.0):
        raise PlanningError(f"duration_s must be finite and > 0, got {duration_s!r}")
    if forcing_transform is None:
        M = np.eye(n)
    else:
        M = np.asarray(forcing_transform, dtype=float)
        if M.shape != (n, n) or not np.all(np.isfinite(M)):
            raise PlanningError(f"forcing_transform must be a finite ({n}, {n}) matrix, got shape {M.shape}")
    return _plan_impl(mp, st, gl, T, M)


def _state_arg(name: str, value: object, n: int) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise PlanningError(f"{name} must be (position, velocity, acceleration) arrays of shape ({n},)") from None
    if a.shape != (3, n):
        raise PlanningError(f"{name} must be (position, velocity, acceleration) of shape ({n},) each, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise PlanningError(f"{name} contains NaN or inf: {a.tolist()}")
    return a


def _plan_impl(mp: TransitionalMP, start: np.ndarray, goal: np.ndarray, T: float, M: np.ndarray) -> TransitionPlan:
    n = mp.n_dims
    sigma = crossing_window_s(goal, T, mp.crossing_reach_m)
    r0 = crossing_target_coefficients(np.array([-T]), sigma)[0, :3] @ goal  # (3, n) [m, m/s, m/s^2]
    norm = np.array([[1.0], [T], [T * T]])
    coefficients = np.zeros((6 + n, n))
    coefficients[:3] = (start - r0) * norm  # e(0), normalised
    coefficients[3 : 3 + n] = M.T
    residual = mp.table_end[:, : 3 + n] @ coefficients[: 3 + n]  # e(1) without correction, normalised
    coefficients[3 + n :] = -CORRECTION_AT_1_INV @ residual
    return TransitionPlan(mp, start, goal, T, M, sigma, residual / norm, coefficients)


def evaluate(plan: TransitionPlan, t_s: np.ndarray) -> TrajectorySamples:
    """Position, velocity and acceleration of a planned transition at times ``t_s``.

    Parameters
    ----------
    t_s : array, shape (m,)
        Times from the start [s]; values < 0 are clamped to 0, values past
        ``T`` follow the goal's constant-acceleration extrapolation.

    Returns
    -------
    TrajectorySamples
        Arrays of shape (m,) and (m, n_dims).
    """
    t = np.maximum(np.asarray(t_s, dtype=float).reshape(-1), 0.0)
    T = plan.duration_s
    rows = hermite_rows(plan.mp.table, t / T)
    e = rows @ plan.coefficients * np.array([[1.0], [1.0 / T], [1.0 / T**2]])
    e[t >= T] = 0.0
    state = crossing_target_coefficients(t - T, plan.sigma_s)[:, :3] @ plan.goal + e
    return TrajectorySamples(t, state[:, 0], state[:, 1], state[:, 2])


def rollout(
    mp: TransitionalMP,
    start: object,
    goal: object,
    duration_s: float,
    *,
    dt_s: float = 0.001,
    forcing_transform: np.ndarray | None = None,
) -> TrajectorySamples:
    """Sample a generalised transition every ``dt_s`` from 0 to the first sample at or after ``T``."""
    if not (math.isfinite(dt_s) and dt_s > 0):
        raise PlanningError(f"dt_s must be finite and > 0, got {dt_s!r}")
    plan = plan_transition(mp, start, goal, duration_s, forcing_transform)
    k = int(math.ceil(plan.duration_s / dt_s - 1e-9))
    return evaluate(plan, np.arange(k + 1) * dt_s)
