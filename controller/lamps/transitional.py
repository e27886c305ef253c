"""Third-order transitional movement primitives, paper eqs. (7)-(19).

A transitional MP carries the tool from the state where one periodic MP
stops, ``(y0, v0, a0)``, into the entry state of the next one,
``(g1, g2, g3)``, in a chosen duration ``T``, with position, velocity and
acceleration continuous at both junctions. The derivation of the consistent
form implemented here is in ``docs/transitional_mp.md``; in short:

* ``tau = T``, time runs as ``s = t / T`` in [0, 1] and the state is scaled,
  ``Y = (y, T dy/dt, T^2 d2y/dt2)``, so eqs. (8)-(9) hold and one learned MP
  plays at any duration. The phase is ``x = exp(-lambda s)`` (eq. 12).
* The crossing target ``r(t)`` is the entry state's constant-acceleration
  extrapolation ``g1 + g2 u + g3 u^2 / 2`` (``u = t - T``; eqs. 14-17 with
  the sign of (17) corrected), multiplied by a Gaussian window of width
  ``sigma`` so the target stays within about ``crossing_reach_m`` of ``g1``
  (``crossing_reach_m = inf`` gives the paper's unwindowed target).
  ``r(T), r'(T), r''(T) = g1, g2, g3`` exactly.
* Eq. (13) with ``(g1hat, g2hat, g3) = (r, T r', T^2 r'')`` plus the target's
  jerk ``T^3 r'''`` as feed-forward (zero for the paper's constant-acceleration
  target) is, for ``e = Y - R``::

      de1/ds = e2,  de2/ds = e3,
      de3/ds = -(1 - x) (p^3 e1 + 3 p^2 e2 + 3 p e3) + f(x)       (eq. 19 gains)

  a linear system whose solution is ``Phi(s) e(0)`` plus the response to the
  forcing term. Both are tabulated once per learned MP (RK4 on
  :data:`N_TABLE` steps, normalised time, so valid for every ``T``).
* The residual ``e(1)`` is therefore known when a transition is built, and a
  quintic ``c(s) = a3 s^3 + a4 s^4 + a5 s^5`` (zero position, velocity and
  acceleration at s = 0) cancels it: the transition lands exactly on
  ``(g1, g2, g3)``. ``y(0) = (y0, v0, a0)`` holds by construction.

At run time a transition is ``target(t) + e(s) + c(s)``: an analytic target,
one cubic-Hermite interpolation of the MP's tables and no integration, so
the cost per 1 kHz step is a few microseconds and independent of the number
of basis functions, and any ``dt`` gives the same (exact) trajectory.

Learning (:func:`learn_transitional`) fits the weights of eq. (10) so that the
generated transition replays the demonstrated positions (least squares, the
default) or, classically, fits the forcing target of eq. (13) by locally
weighted regression.

Public API: :class:`TransitionalMP` (``to_dict`` / ``from_dict``);
:func:`plan_transition` -> :class:`TransitionPlan`, :func:`evaluate`,
:func:`rollout` -> :class:`TrajectorySamples`; :func:`similarity_transform`
for the ``forcing_transform``. Learning is in :mod:`.transitional_learn`
(:func:`learn_transitional`), the 1 kHz step API in
:mod:`.transitional_runner` (:class:`TransitionalRunner`,
``update(dt_s) -> TransitionStatus``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from scipy.interpolate import make_lsq_spline

from .errors import PlanningError, SkillFileError

#: Steps of the tabulated fundamental solutions over the normalised duration.
N_TABLE = 2048
#: Format tag and version written by :meth:`TransitionalMP.to_dict`.
KIND = "transitional_mp"
VERSION = 1
#: A segment needs at least this many samples and this duration [s] to be learned.
MIN_SAMPLES = 10
MIN_DURATION_S = 0.1

#: Defaults (see docs/transitional_mp.md, "Choosing p, lambda and the window").
DEFAULT_P = 20.0
DEFAULT_LAMBDA = 8.0
DEFAULT_N_BASIS = 40
DEFAULT_REACH_M = 0.1
#: Weight of e(T) = 0 against the mean squared position error in the path fit.
TERMINAL_FIT_WEIGHT = 1.0
#: Basis width relative to the spacing of neighbouring centres.
BASIS_OVERLAP = 0.5

# Position/velocity/acceleration of s^3, s^4, s^5 at s = 1 (terminal correction).
_CORR_AT_1_INV = np.linalg.inv(np.array([[1.0, 1.0, 1.0], [3.0, 4.0, 5.0], [6.0, 12.0, 20.0]]))


def _correction_table(n_steps: int) -> np.ndarray:
    """Rows position, velocity, acceleration, jerk of ``s^3, s^4, s^5`` on ``s = k / n_steps``; shape (K+1, 4, 3)."""
    s = np.linspace(0.0, 1.0, n_steps + 1)
    one = np.ones_like(s)
    return np.stack(
        [np.stack([s**3, s**4, s**5], 1), np.stack([3 * s**2, 4 * s**3, 5 * s**4], 1),
         np.stack([6 * s, 12 * s**2, 20 * s**3], 1), np.stack([6 * one, 24 * s, 60 * s**2], 1)],
        axis=1,
    )


_CORRECTION_TABLE = _correction_table(N_TABLE)


class TransitionStatus(IntEnum):
    """Result of :meth:`TransitionalRunner.update` (ruckig style: negative = error)."""

    ERROR_INVALID_INPUT = -100
    WORKING = 0
    FINISHED = 1


class TrajectorySamples(NamedTuple):
    """A sampled trajectory, shared by the MP and the baselines.

    Attributes
    ----------
    t_s : array, shape (m,)
        Sample times from the transition start [s].
    position_m, velocity_m_s, acceleration_m_s2 : arrays, shape (m, n_dims)
    """

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray


# --------------------------------------------------------------------------
# maths on arrays


def phase(s: np.ndarray | float, lambda_: float) -> np.ndarray | float:
    """Phase ``x = exp(-lambda s)`` at normalised time ``s = t / T`` (solution of eq. 12, tau = T)."""
    return np.exp(-lambda_ * np.asarray(s, dtype=float))


def basis_centres_widths(n_basis: int, lambda_: float, overlap: float = BASIS_OVERLAP) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``c_i`` and widths ``h_i`` of eq. (11), evenly spaced in time.

    Returns
    -------
    centres : array, shape (n_basis,)
        ``exp(-lambda s_i)`` for ``s_i`` evenly spaced on [0, 1].
    widths : array, shape (n_basis,)
        ``h_i = 1 / (2 (overlap * d_i)^2)`` with ``d_i`` the gap to the next centre.
    """
    centres = np.exp(-lambda_ * np.linspace(0.0, 1.0, n_basis))
    gaps = np.abs(np.diff(centres))
    gaps = np.append(gaps, gaps[-1])
    return centres, 1.0 / (2.0 * (overlap * gaps) ** 2)


def forcing_term(x: np.ndarray, weights: np.ndarray, centres: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Eqs. (10)-(11): ``f(x) = sum_i w_i psi_i(x) / sum_i psi_i(x) * x``.

    Parameters
    ----------
    x : array, shape (m,)
        Phase values.
    weights : array, shape (N, n_dims)
    centres, widths : arrays, shape (N,)

    Returns
    -------
    f : array, shape (m, n_dims)
        In normalised jerk units (real jerk contribution ``f / T^3`` [m/s^3]).
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    psi = np.exp(-widths * (x[:, None] - centres) ** 2)
    return (psi @ weights) / np.maximum(psi.sum(axis=1, keepdims=True), 1e-300) * x[:, None]


def crossing_window_s(goal: np.ndarray, duration_s: float, reach_m: float) -> float:
    """Width ``sigma`` [s] of the crossing target's window.

    ``sigma = min(T / 4, reach / |g2|, sqrt(reach / |g3|))`` keeps the target
    within about ``reach`` of ``g1`` (the windowed velocity and acceleration
    parts peak at ``0.61 |g2| sigma`` and ``0.37 |g3| sigma^2``); ``T / 4``
    makes the window negligible (``exp(-8)``) at ``t = 0``. ``reach = inf``
    returns ``inf``: no window, the paper's constant-acceleration target.

    Parameters
    ----------
    goal : array, shape (3, n_dims)
        Entry state ``(g1, g2, g3)`` [m, m/s, m/s^2].
    """
    if math.isinf(reach_m):
        return math.inf
    sigma = duration_s / 4.0
    v, a = float(np.linalg.norm(goal[1])), float(np.linalg.norm(goal[2]))
    if v > 0.0:
        sigma = min(sigma, reach_m / v)
    if a > 0.0:
        sigma = min(sigma, math.sqrt(reach_m / a))
    return sigma


def crossing_target_coefficients(u_s: np.ndarray, sigma_s: float) -> np.ndarray:
    """Coefficients of the crossing target ``r(u) = g1 + w(u) (g2 u + g3 u^2 / 2)``.

    ``w(u) = exp(-u^2 / (2 sigma^2))``; ``u = t - T <= 0``. For ``u > 0``
    (after the transition) the window is dropped: ``r`` is the plain
    constant-acceleration extrapolation of the goal.

    Parameters
    ----------
    u_s : array, shape (m,)
        Time relative to the end of the transition [s].
    sigma_s : float
        Window width [s] (``inf``: no window).

    Returns
    -------
    coef : array, shape (m, 4, 3)
        ``coef[k, d, j]``: the d-th time derivative (position, velocity,
        acceleration, jerk) of ``r`` at ``u_s[k]`` is ``sum_j coef[k, d, j] g_j``
        with ``(g_0, g_1, g_2) = (g1, g2, g3)``.
    """
    u = np.asarray(u_s, dtype=float).reshape(-1)
    a = 0.0 if math.isinf(sigma_s) else -1.0 / sigma_s**2
    a = np.where(u > 0.0, 0.0, a)
    w0 = np.exp(0.5 * a * u * u)
    w1 = a * u * w0
    w2 = (a + a * a * u * u) * w0
    w3 = (3.0 * a * a * u + a**3 * u**3) * w0
    coef = np.zeros((len(u), 4, 3))
    coef[:, 0, 0] = 1.0
    coef[:, 0, 1] = w0 * u
    coef[:, 0, 2] = 0.5 * w0 * u * u
    coef[:, 1, 1] = w1 * u + w0
    coef[:, 1, 2] = 0.5 * w1 * u * u + w0 * u
    coef[:, 2, 1] = w2 * u + 2.0 * w1
    coef[:, 2, 2] = 0.5 * w2 * u * u + 2.0 * w1 * u + w0
    coef[:, 3, 1] = w3 * u + 3.0 * w2
    coef[:, 3, 2] = 0.5 * w3 * u * u + 3.0 * w2 * u + 3.0 * w1
    return coef


def gate_and_gains(s: np.ndarray, p: float, lambda_: float) -> tuple[np.ndarray, np.ndarray]:
    """Gate ``1 - x(s)`` of eq. (13) and the error-feedback gains of eqs. (18)-(19).

    With ``alpha = 3p, beta = p, gamma = p/3``: ``alpha beta gamma = p^3``,
    ``alpha beta = 3 p^2``, ``alpha = 3 p``, i.e. ``P(s) = (s + p/tau)^3``.

    Returns
    -------
    gate : array, shape (m,)
    gains : array, shape (3,)
        ``(p^3, 3 p^2, 3 p)``.
    """
    return 1.0 - phase(s, lambda_), np.array([p**3, 3.0 * p**2, 3.0 * p])


def fundamental_tables(
    p: float, lambda_: float, weights: np.ndarray, centres: np.ndarray, widths: np.ndarray, n_steps: int = N_TABLE
) -> tuple[np.ndarray, np.ndarray]:
    """Tabulate the error dynamics' responses on ``s = k / n_steps``, k = 0..n_steps.

    Integrates ``e' = A(s) e + (0, 0, f(s))`` with classical RK4 (step
    ``1 / n_steps``; with ``p <= 60`` the step is ``p h <= 0.03``, RK4's
    relative error ~1e-9). The per-step affine maps are built for all steps at
    once, then chained.

    Returns
    -------
    phi : array, shape (n_steps + 1, 4, 3)
        Rows: ``e1, e2, e3, de3/ds`` for unit initial error in column j, no forcing.
    forced : array, shape (n_steps + 1, 4, n_dims)
        Rows as ``phi`` for zero initial error and the learned forcing term.
    """
    h = 1.0 / n_steps
    s_half = np.arange(2 * n_steps + 1) * (0.5 * h)
    gate, gains = gate_and_gains(s_half, p, lambda_)
    f_half = forcing_term(phase(s_half, lambda_), weights, centres, widths)  # (2K+1, n)
    A = np.zeros((2 * n_steps + 1, 3, 3))
    A[:, 0, 1] = A[:, 1, 2] = 1.0
    A[:, 2, :] = -gate[:, None] * gains
    A0, Am, A1 = A[0:-1:2], A[1::2], A[2::2]
    n = weights.shape[1]
    B = np.zeros((2 * n_steps + 1, 3, n))
    B[:, 2, :] = f_half
    b0, bm, b1 = B[0:-1:2], B[1::2], B[2::2]
    eye = np.eye(3)
    K1, c1 = A0, b0
    K2, c2 = Am + 0.5 * h * Am @ K1, 0.5 * h * Am @ c1 + bm
    K3, c3 = Am + 0.5 * h * Am @ K2, 0.5 * h * Am @ c2 + bm
    K4, c4 = A1 + h * A1 @ K3, h * A1 @ c3 + b1
    P = eye + (h / 6.0) * (K1 + 2.0 * K2 + 2.0 * K3 + K4)
    Q = (h / 6.0) * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    state = np.zeros((n_steps + 1, 3, 3 + n))
    state[0, :, :3] = eye
    cur = state[0]
    for k in range(n_steps):
        nxt = P[k] @ cur
        nxt[:, 3:] += Q[k]
        state[k + 1] = nxt
        cur = nxt
    jerk = np.einsum("kj,kjm->km", A[::2, 2, :], state)
    jerk[:, 3:] += f_half[::2]
    full = np.concatenate([state, jerk[:, None, :]], axis=1)
    return full[:, :, :3], full[:, :, 3:]


def forcing_target(
    s: np.ndarray, kinematics: np.ndarray, goal: np.ndarray, duration_s: float, p: float, lambda_: float, sigma_s: float
) -> np.ndarray:
    """The forcing term that makes the error form of eq. (13) reproduce a demonstration exactly.

    ``f = de3/ds + (1 - x) (p^3 e1 + 3 p^2 e2 + 3 p e3)`` with ``e = Y - R``.

    Parameters
    ----------
    s : array, shape (m,)
        Normalised times ``t / T`` of the samples.
    kinematics : array, shape (m, 4, n_dims)
        Position, velocity, acceleration, jerk of the demonstration [m, m/s, m/s^2, m/s^3].
    goal : array, shape (3, n_dims)
        Its end state.

    Returns
    -------
    array, shape (m, n_dims)
        Normalised jerk units.
    """
    T = duration_s
    coef = crossing_target_coefficients((s - 1.0) * T, sigma_s)
    scale = np.array([1.0, T, T * T, T**3])[:, None]
    e = (kinematics - coef @ goal) * scale
    gate, gains = gate_and_gains(s, p, lambda_)
    return e[:, 3] + gate[:, None] * np.einsum("j,mjn->mn", gains, e[:, :3])


def fit_forcing_lwr(
    s: np.ndarray, f_target: np.ndarray, centres: np.ndarray, widths: np.ndarray, lambda_: float
) -> np.ndarray:
    """Locally weighted regression of eq. (10)'s weights, one basis function at a time.

    ``w_i = sum_j psi_i(x_j) x_j f_j / sum_j psi_i(x_j) x_j^2``, the classic
    DMP fit of a model ``f = w_i x`` local to basis i. The target is first
    interpolated onto a uniform grid of at least ``10 N`` points in ``s`` so
    that every basis function sees data however short the segment.

    Parameters
    ----------
    s : array, shape (m,)
        Normalised sample times in [0, 1], increasing.
    f_target : array, shape (m, n_dims)
        From :func:`forcing_target`.
    centres, widths : arrays, shape (N,)

    Returns
    -------
    weights : array, shape (N, n_dims)
    """
    grid = np.linspace(0.0, 1.0, max(1001, 10 * len(centres)))
    f = np.column_stack([np.interp(grid, s, f_target[:, d]) for d in range(f_target.shape[1])])
    x = phase(grid, lambda_)
    psi = np.exp(-widths * (x[:, None] - centres) ** 2)
    return (psi * x[:, None]).T @ f / (psi * (x * x)[:, None]).sum(axis=0)[:, None]


def fit_forcing_to_path(
    s: np.ndarray,
    y: np.ndarray,
    start: np.ndarray,
    goal: np.ndarray,
    duration_s: float,
    p: float,
    lambda_: float,
    sigma_s: float,
    centres: np.ndarray,
    widths: np.ndarray,
) -> np.ndarray:
    """Weights whose uncorrected transition is closest to the demonstrated positions.

    For fixed gains, start, goal and duration the generated position is
    affine in the weights, ``y(s) = b(s) + H(s) w`` (columns of ``H``: the
    response to one unit weight, from :func:`fundamental_tables`). Solving
    this least-squares problem fits positions, not a forcing target built
    from third derivatives of noisy data, which is what makes it robust:
    see docs/transitional_mp.md for the comparison with LWR. Three extra
    rows ask for ``e(1) = 0`` (weight :data:`TERMINAL_FIT_WEIGHT` relative to
    the mean squared position error, normalised units) so that the fitted
    system lands on the goal by itself and the terminal correction stays small.

    Parameters
    ----------
    s : array, shape (m,)
        Normalised sample times in [0, 1].
    y : array, shape (m, n_dims)
        Demonstrated positions [m].
    start, goal : arrays, shape (3, n_dims)
        Boundary states used by the replay [m, m/s, m/s^2].
    centres, widths : arrays, shape (N,)

    Returns
    -------
    weights : array, shape (N, n_dims)
    """
    n_basis = len(centres)
    phi, forced = fundamental_tables(p, lambda_, np.eye(n_basis), centres, widths)
    end, hermite = _hermite_table(np.concatenate([phi, forced], axis=2))
    rows = _rows_at(hermite, s)[:, 0]  # (m, 3 + N): position row
    T = duration_s
    r0 = crossing_target_coefficients(np.array([-T]), sigma_s)[0, :3] @ goal
    e0 = (start - r0) * np.array([[1.0], [T], [T * T]])
    base = crossing_target_coefficients((s - 1.0) * T, sigma_s)[:, 0] @ goal + rows[:, :3] @ e0
    # Terminal rows: the uncorrected system should itself land on the goal
    # (e(1) = 0), so the correction stays a small fix and the weights stay
    # meaningful when the MP is generalised.
    terminal = np.sqrt(len(s)) * TERMINAL_FIT_WEIGHT
    design = np.vstack([rows[:, 3:], terminal * end[:, 3:]])
    rhs = np.vstack([y - base, -terminal * end[:, :3] @ e0])
    col = np.maximum(np.linalg.norm(design, axis=0), 1e-300)
    a = design / col
    gram = a.T @ a
    gram[np.diag_indices_from(gram)] += 1e-10 * np.trace(gram) / n_basis
    return np.linalg.solve(gram, a.T @ rhs) / col[:, None]


def _rows_at(hermite: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Cubic-Hermite interpolation of a table from :func:`_hermite_table` at ``s``; shape (m, 3, cols)."""
    k = hermite.shape[0]
    z = np.clip(np.asarray(s, dtype=float), 0.0, 1.0) * k
    i = np.minimum(z.astype(int), k - 1)
    w = _hermite_weights(z - i)
    return np.einsum("mk,mkj->mj", w, hermite[i].reshape(len(z), 4, -1)).reshape(len(z), 3, -1)


def smooth_kinematics(
    t_s: np.ndarray, y: np.ndarray, knot_spacing_s: float = 0.04
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Position and its first three derivatives from one least-squares quintic spline.

    The forcing target of eq. (13) combines position, velocity, acceleration
    and jerk with gains up to ``p^3``; if the four channels are not
    derivatives of one function (separately filtered channels, e.g.
    Savitzky-Golay per derivative order, disagree by a few percent on a 2 Hz
    circle), the replay is off by centimetres. A least-squares B-spline of
    degree 5 with knots every ``knot_spacing_s`` smooths the noise and gives
    exactly consistent derivatives.

    Parameters
    ----------
    t_s : array, shape (m,)
        Uniform sample times [s].
    y : array, shape (m, n_dims)
        Positions [m].
    knot_spacing_s : float
        Interior knot spacing [s] (about the shortest feature kept).

    Returns
    -------
    pos, vel, acc, jerk : arrays, shape (m, n_dims)
        [m], [m/s], [m/s^2], [m/s^3].
    """
    t = np.asarray(t_s, dtype=float)
    k = 5
    n_int = max(0, min(int(round((t[-1] - t[0]) / knot_spacing_s)) - 1, (len(t) - k - 1) // 2))
    inner = np.linspace(t[0], t[-1], n_int + 2)
    knots = np.concatenate([[t[0]] * k, inner, [t[-1]] * k])
    spline = make_lsq_spline(t, y, knots, k=k)
    return tuple(spline.derivative(d)(t) if d else spline(t) for d in range(4))


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
    axis, c = np.cross(a, b), float(a @ b)
    sin = float(np.linalg.norm(axis))
    if sin < 1e-12:
        if c > 0:
            return scale * np.eye(3)
        perp = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        perp /= np.linalg.norm(perp)
        return scale * (2.0 * np.outer(perp, perp) - np.eye(3))
    k = axis / sin
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return scale * (np.eye(3) + sin * kx + (1.0 - c) * kx @ kx)


# --------------------------------------------------------------------------
# the learned primitive


@dataclass(frozen=True, eq=False)
class TransitionalMP:
    """A learned third-order transitional MP (paper eqs. 7-19).

    Attributes
    ----------
    weights : array, shape (N, n_dims)
        Forcing-term weights ``w_i`` of eq. (10), normalised jerk units, in
        the demonstration's frame.
    centres : array, shape (N,)
        Basis centres ``c_i`` in phase, eq. (11).
    widths : array, shape (N,)
        Basis widths ``h_i``, eq. (11).
    p : float
        Pole of eq. (19): ``P(s) = (s + p / T)^3``; dimensionless (per
        duration), in [1, 60].
    lambda_ : float
        Phase decay of eq. (12), ``x = exp(-lambda t / T)``, in [0.1, 30].
    crossing_reach_m : float
        Bound on how far the crossing target strays from ``g1`` [m]
        (``inf``: the paper's unwindowed target).
    demo_duration_s : float
        Duration of the demonstrated segment [s].
    demo_start : array, shape (3, n_dims)
        Demonstrated start state: position [m], velocity [m/s], acceleration [m/s^2].
    demo_goal : array, shape (3, n_dims)
        Demonstrated end state, same rows.
    demo_displacement_m : array, shape (n_dims,)
        ``demo_goal[0] - demo_start[0]``.
    demo_rmse_m : float
        RMS position error of the MP replaying its own demonstration [m].

    Raises
    ------
    SkillFileError
        A field has the wrong shape, is not finite, or is out of range.
    """

    weights: np.ndarray
    centres: np.ndarray
    widths: np.ndarray
    p: float
    lambda_: float
    crossing_reach_m: float
    demo_duration_s: float
    demo_start: np.ndarray
    demo_goal: np.ndarray
    demo_displacement_m: np.ndarray
    demo_rmse_m: float = 0.0
    _end: np.ndarray = field(init=False, repr=False, compare=False)
    _hermite: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("p", "lambda_", "crossing_reach_m", "demo_duration_s", "demo_rmse_m"):
            object.__setattr__(self, name, _scalar_field(name, getattr(self, name)))
        w = _array_field("weights", self.weights, 2)
        n_basis, n = w.shape
        if n_basis < 2 or n < 1:
            raise SkillFileError(f"TransitionalMP.weights: need shape (N >= 2, n_dims >= 1), got {w.shape}")
        c = _array_field("centres", self.centres, 1, (n_basis,))
        h = _array_field("widths", self.widths, 1, (n_basis,))
        if np.any(h <= 0):
            raise SkillFileError("TransitionalMP.widths: every width must be > 0")
        for name, value, lo, hi in (("p", self.p, 1.0, 60.0), ("lambda_", self.lambda_, 0.1, 30.0)):
            if not lo <= value <= hi:
                raise SkillFileError(f"TransitionalMP.{name}: must be in [{lo}, {hi}], got {value!r}")
        if not self.crossing_reach_m > 0:
            raise SkillFileError(
                f"TransitionalMP.crossing_reach_m: must be > 0 (inf allowed), got {self.crossing_reach_m!r}"
            )
        if not (math.isfinite(self.demo_duration_s) and self.demo_duration_s > 0):
            raise SkillFileError(
                f"TransitionalMP.demo_duration_s: must be finite and > 0, got {self.demo_duration_s!r}"
            )
        if not (math.isfinite(self.demo_rmse_m) and self.demo_rmse_m >= 0):
            raise SkillFileError(f"TransitionalMP.demo_rmse_m: must be finite and >= 0, got {self.demo_rmse_m!r}")
        start = _array_field("demo_start", self.demo_start, 2, (3, n))
        goal = _array_field("demo_goal", self.demo_goal, 2, (3, n))
        disp = _array_field("demo_displacement_m", self.demo_displacement_m, 1, (n,))
        for name, value in (("weights", w), ("centres", c), ("widths", h), ("demo_start", start),
                            ("demo_goal", goal), ("demo_displacement_m", disp)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        phi, forced = fundamental_tables(self.p, self.lambda_, w, c, h)
        end, hermite = _hermite_table(np.concatenate([phi, forced, _CORRECTION_TABLE], axis=2))
        object.__setattr__(self, "_end", end)
        object.__setattr__(self, "_hermite", hermite)

    @property
    def n_dims(self) -> int:
        return self.weights.shape[1]

    @property
    def n_basis(self) -> int:
        return self.weights.shape[0]

    def to_dict(self) -> dict:
        """Plain-JSON description (lists and floats); ``inf`` reach is written as the string ``"inf"``."""
        return {
            "kind": KIND,
            "version": VERSION,
            "weights": self.weights.tolist(),
            "centres": self.centres.tolist(),
            "widths": self.widths.tolist(),
            "p": self.p,
            "lambda": self.lambda_,
            "crossing_reach_m": "inf" if math.isinf(self.crossing_reach_m) else self.crossing_reach_m,
            "demo_duration_s": self.demo_duration_s,
            "demo_start": self.demo_start.tolist(),
            "demo_goal": self.demo_goal.tolist(),
            "demo_displacement_m": self.demo_displacement_m.tolist(),
            "demo_rmse_m": self.demo_rmse_m,
        }

    @classmethod
    def from_dict(cls, d: object) -> "TransitionalMP":
        """Inverse of :meth:`to_dict`; raises :class:`SkillFileError` naming the bad field."""
        if not isinstance(d, dict):
            raise SkillFileError(f"transitional MP: expected an object, got {type(d).__name__}")
        if d.get("kind", KIND) != KIND:
            raise SkillFileError(f"transitional MP: kind must be {KIND!r}, got {d.get('kind')!r}")
        if d.get("version", VERSION) != VERSION:
            raise SkillFileError(
                f"transitional MP: unsupported version {d.get('version')!r} (this code reads {VERSION})"
            )
        keys = ("weights", "centres", "widths", "p", "lambda", "crossing_reach_m", "demo_duration_s",
                "demo_start", "demo_goal", "demo_displacement_m")
        missing = [k for k in keys if k not in d]
        if missing:
            raise SkillFileError(f"transitional MP: missing field(s) {missing}")
        scalars = ("p", "lambda", "crossing_reach_m", "demo_duration_s", "demo_rmse_m")
        values = {}
        for k in keys + ("demo_rmse_m",):
            if k not in d:
                continue
            raw = d[k]
            if k in scalars:
                if k == "crossing_reach_m" and raw == "inf":
                    raw = math.inf
                if isinstance(raw, bool) or not isinstance(raw, (int, float)):
                    raise SkillFileError(f"TransitionalMP.{k}: expected a number, got {raw!r:.80}")
                raw = float(raw)
            values[k] = raw
        values["lambda_"] = values.pop("lambda")
        return cls(**values)


def _scalar_field(name: str, value: object) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SkillFileError(f"TransitionalMP.{name}: expected a number, got {value!r:.80}") from None


def _array_field(name: str, value: object, ndim: int, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SkillFileError(f"TransitionalMP.{name}: not an array of numbers") from None
    if a.ndim != ndim or (shape is not None and a.shape != shape):
        want = shape if shape is not None else f"{ndim}-D"
        raise SkillFileError(f"TransitionalMP.{name}: expected shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SkillFileError(f"TransitionalMP.{name}: contains NaN or inf; every value must be finite")
    return a


# --------------------------------------------------------------------------
# generalisation: one transition


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
    residual = mp._end[:, : 3 + n] @ coefficients[: 3 + n]  # e(1) without correction, normalised
    coefficients[3 + n :] = -_CORR_AT_1_INV @ residual
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
    rows = _rows_at(plan.mp._hermite, t / T)
    e = rows @ plan.coefficients * np.array([[1.0], [1.0 / T], [1.0 / T**2]])
    e[t >= T] = 0.0
    state = crossing_target_coefficients(t - T, plan.sigma_s)[:, :3] @ plan.goal + e
    return TrajectorySamples(t, state[:, 0], state[:, 1], state[:, 2])


def _hermite_table(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-interval cubic-Hermite data of a table of values and derivatives.

    Parameters
    ----------
    table : array, shape (K + 1, 4, m)
        Rows: ``e1, e2, e3, de3/ds`` (each row the derivative of the one
        before) on ``s = k / K``.

    Returns
    -------
    end : array, shape (3, m)
        Rows 0-2 at ``s = 1``.
    hermite : array, shape (K, 4 * 3 * m)
        For interval k: ``[v_k, h d_k, v_k+1, h d_k+1]`` with ``v`` rows 0-2 and
        ``d`` rows 1-3, so that ``weights @ hermite[k]`` interpolates rows 0-2.
    """
    h = 1.0 / (len(table) - 1)
    hermite = np.stack([table[:-1, :3], h * table[:-1, 1:], table[1:, :3], h * table[1:, 1:]], axis=1)
    hermite = np.ascontiguousarray(hermite.reshape(len(table) - 1, -1))
    end = table[-1, :3].copy()
    hermite.setflags(write=False)
    end.setflags(write=False)
    return end, hermite


def _hermite_weights(a: np.ndarray) -> np.ndarray:
    a2, a3 = a * a, a * a * a
    return np.stack([2 * a3 - 3 * a2 + 1, a3 - 2 * a2 + a, -2 * a3 + 3 * a2, a3 - a2], axis=-1)


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
