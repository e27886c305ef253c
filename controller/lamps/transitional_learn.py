"""Learning a transitional MP from a demonstrated segment (see docs/transitional_mp.md, section 7)."""

from __future__ import annotations


import numpy as np

from .derivatives import resample_uniform, smooth_derivatives
from .errors import LampsError, LearningError
from .transitional import (
    DEFAULT_LAMBDA,
    DEFAULT_N_BASIS,
    DEFAULT_P,
    DEFAULT_REACH_M,
    MIN_DURATION_S,
    MIN_SAMPLES,
    TransitionalMP,
    basis_centres_widths,
    crossing_window_s,
    evaluate,
    fit_forcing_lwr,
    fit_forcing_to_path,
    forcing_target,
    plan_transition,
    smooth_kinematics,
)


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
