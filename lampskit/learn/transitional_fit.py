"""Learning a transitional MP from a demonstrated segment (see docs/transitional_mp.md, section 7)."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import make_lsq_spline

from lampskit.core.transitional import (
    DEFAULT_LAMBDA,
    DEFAULT_N_BASIS,
    DEFAULT_P,
    DEFAULT_REACH_M,
    MIN_DURATION_S,
    MIN_SAMPLES,
    TransitionalMP,
)
from lampskit.core.transitional_maths import (
    basis_centres_widths,
    crossing_target_coefficients,
    crossing_window_s,
    fundamental_tables,
    gate_and_gains,
    hermite_rows,
    hermite_table,
    phase,
)
from lampskit.core.transitional_plan import evaluate, plan_transition
from lampskit.errors import LampsError, LearningError
from lampskit.learn.derivatives import resample_uniform, smooth_derivatives


def learn_transitional(
    t_s: np.ndarray,
    y: np.ndarray,
    *,
    n_basis: int = DEFAULT_N_BASIS,
    p: float = DEFAULT_P,
    lambda_: float = DEFAULT_LAMBDA,
    crossing_reach_m: float = DEFAULT_REACH_M,
    smoothing_window_s: float = 0.08,
    rate_hz: float | None = None,
    regression: str = "path",
) -> TransitionalMP:
    """Learn a transitional MP from one demonstrated segment.

    The segment is resampled uniformly; its start and end states (the MP's
    ``demo_start`` / ``demo_goal``) come from smoothed derivatives. The
    weights are then fitted (default ``regression="path"``) so that the
    transition generated with those boundary states and the demonstrated
    duration is closest to the demonstrated positions; or, classically
    (``"lwr"``), the demonstration is rolled through the error form of
    eq. (13) to a forcing target that locally weighted regression fits.
    ``demo_rmse_m`` records how well the result replays the segment.

    Parameters
    ----------
    t_s : array, shape (T,)
        Sample times [s], strictly increasing.
    y : array, shape (T, n_dims)
        Positions [m].
    n_basis : int
        Number of basis functions N (>= 2).
    p, lambda_, crossing_reach_m : float
        See :class:`TransitionalMP`.
    smoothing_window_s : float
        ``"path"``: Savitzky-Golay window [s] for the boundary states
        (:func:`smooth_derivatives`); ``"lwr"``: knot spacing [s] of the
        quintic spline all four channels come from (:func:`smooth_kinematics`).
    rate_hz : float, optional
        Resampling rate [Hz]; default the segment's mean rate.
    regression : {"path", "lwr"}
        ``"path"``: least squares on the generated positions
        (:func:`fit_forcing_to_path`); ``"lwr"``: the classic forcing target of
        eq. (13) fitted by locally weighted regression (:func:`fit_forcing_lwr`).

    Raises
    ------
    LearningError
        Fewer than :data:`MIN_SAMPLES` samples, shorter than
        :data:`MIN_DURATION_S`, non-finite or non-increasing samples, or bad parameters.
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if y.ndim != 2 or len(y) != len(t):
        raise LearningError(f"transitional segment: y must have shape ({len(t)}, n_dims), got {y.shape}")
    if len(t) < MIN_SAMPLES:
        raise LearningError(f"transitional segment too short: {len(t)} samples, need at least {MIN_SAMPLES}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise LearningError("transitional segment contains NaN or inf; every sample must be finite")
    if np.any(np.diff(t) <= 0):
        raise LearningError("transitional segment: timestamps must increase strictly")
    duration = float(t[-1] - t[0])
    if duration < MIN_DURATION_S:
        raise LearningError(f"transitional segment too short: {duration:.3f} s, need at least {MIN_DURATION_S} s")
    if regression not in ("path", "lwr"):
        raise LearningError(f"regression must be 'path' or 'lwr', got {regression!r}")
    if not (isinstance(n_basis, int) and n_basis >= 2):
        raise LearningError(f"n_basis must be an integer >= 2, got {n_basis!r}")
    if not 1.0 <= p <= 60.0 or not 0.1 <= lambda_ <= 30.0 or not crossing_reach_m > 0:
        raise LearningError(
            f"need p in [1, 60], lambda_ in [0.1, 30], crossing_reach_m > 0; got {p}, {lambda_}, {crossing_reach_m}"
        )
    tu, yu = resample_uniform(t, y, rate_hz)
    T = float(tu[-1] - tu[0])
    s = (tu - tu[0]) / T
    centres, widths = basis_centres_widths(n_basis, lambda_)
    if regression == "lwr":
        kin = np.stack(smooth_kinematics(tu - tu[0], yu, smoothing_window_s), axis=1)  # (m, 4, n)
        start, goal = kin[0, :3], kin[-1, :3]
        sigma = crossing_window_s(goal, T, crossing_reach_m)
        weights = fit_forcing_lwr(s, forcing_target(s, kin, goal, T, p, lambda_, sigma), centres, widths, lambda_)
    else:
        try:
            pos, vel, acc = smooth_derivatives(yu, float(tu[1] - tu[0]), smoothing_window_s)
        except LampsError as exc:
            raise LearningError(f"transitional segment: {exc}") from None
        start, goal = np.stack([pos[0], vel[0], acc[0]]), np.stack([pos[-1], vel[-1], acc[-1]])
        sigma = crossing_window_s(goal, T, crossing_reach_m)
        weights = fit_forcing_to_path(s, yu, start, goal, T, p, lambda_, sigma, centres, widths)
    mp = TransitionalMP(weights, centres, widths, p, lambda_, crossing_reach_m, T, start, goal, goal[0] - start[0])
    replay = evaluate(plan_transition(mp, start, goal, T), t - t[0])
    rmse = float(np.sqrt(np.mean(np.sum((replay.position_m - y) ** 2, axis=1))))
    object.__setattr__(mp, "demo_rmse_m", rmse)  # not yet shared: cheaper than rebuilding the tables
    return mp


#: Weight of e(T) = 0 against the mean squared position error in the path fit.
TERMINAL_FIT_WEIGHT = 1.0


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
    x = np.asarray(phase(grid, lambda_))
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
    end, hermite = hermite_table(np.concatenate([phi, forced], axis=2))
    rows = hermite_rows(hermite, s)[:, 0]  # (m, 3 + N): position row
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
