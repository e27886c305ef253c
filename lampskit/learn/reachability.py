"""Steps 1-4 of the segmentation: smoothed positions, points resampled by distance, the reachability threshold.

Pure functions on arrays (:mod:`lampskit.learn.segmentation` explains the
method): Savitzky-Golay smoothing, the distance-resampling step and the kept
points, Otsu's threshold on the log reachability clamped to
``[BETA_LO, BETA_HI]`` times the single-pass reachability, and clusters read
from an OPTICS ordering at that threshold.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from lampskit.errors import SegmentationError
from lampskit.learn.optics import OpticsResult

#: Savitzky-Golay window of the position smoothing [s].
SMOOTH_WINDOW_S = 0.05
#: Automatic threshold clamp, as fractions of the single-pass reachability.
BETA_LO, BETA_HI = 0.4, 0.7


def otsu_threshold(values: np.ndarray) -> float:
    """Otsu's threshold of ``values`` (shape (N,), at least two distinct), exactly over the sorted values.

    Returns the midpoint of the two values either side of the split with the
    largest between-class variance ``w0 w1 (mu0 - mu1)^2``.
    """
    v = np.sort(np.asarray(values, dtype=float).ravel())
    if len(v) < 2 or v[0] == v[-1]:
        raise SegmentationError(f"Otsu's threshold needs at least two distinct values, got {len(v)} value(s)")
    n = len(v)
    csum = np.cumsum(v)
    w0 = np.arange(1, n)  # split after index i: class 0 = v[: i + 1]
    w1 = n - w0
    score = w0 * w1 * (csum[:-1] / w0 - (csum[-1] - csum[:-1]) / w1) ** 2
    score[v[1:] == v[:-1]] = -1.0  # no split between equal values
    i = int(np.argmax(score))
    return float(0.5 * (v[i] + v[i + 1]))


def single_pass_reachability(min_samples: int, step_m: float) -> float:
    """Reachability [m] along a straight path crossed once and resampled every ``step_m``."""
    return 0.5 * (min_samples - 1) * step_m


def reachability_threshold(reachability_plot: np.ndarray, min_samples: int, step_m: float) -> float:
    """The automatic threshold [m]: Otsu on log reachability, clamped to ``[BETA_LO, BETA_HI] * R1``.

    Parameters
    ----------
    reachability_plot : array, shape (M,)
        Reachability in OPTICS order [m] (non-finite values are ignored).
    min_samples : int
    step_m : float
        Distance-resampling step [m].
    """
    r1 = single_pass_reachability(min_samples, step_m)
    r = np.asarray(reachability_plot, dtype=float)
    r = r[np.isfinite(r) & (r > 0)]
    if len(r) < 2 or r.min() == r.max():
        return BETA_LO * r1
    otsu = float(np.exp(otsu_threshold(np.log(r))))
    return float(np.clip(otsu, BETA_LO * r1, BETA_HI * r1))


def dbscan_labels(result: OpticsResult, eps: float) -> np.ndarray:
    """Clusters at ``eps`` [m] read from the OPTICS ordering (sklearn's ``cluster_optics_dbscan``).

    Returns labels of shape (M,), -1 for noise.
    """
    far = result.reachability > eps
    core = result.core_distances <= eps
    labels = np.zeros(len(far), dtype=int)
    order = result.ordering
    labels[order] = np.cumsum(far[order] & core[order]) - 1
    labels[far & ~core] = -1
    return labels


def smooth_positions(position_m: np.ndarray, rate_hz: float, deriv: int = 0) -> np.ndarray:
    """Savitzky-Golay smoothed positions [m] (or velocities [m/s] with ``deriv=1``), shape (T, 3)."""
    n = len(position_m)
    win = min(max(int(round(SMOOTH_WINDOW_S * rate_hz)) | 1, 5), n if n % 2 else n - 1)
    return savgol_filter(position_m, win, 2, deriv=deriv, delta=1.0 / rate_hz, axis=0, mode="interp")


def resampling_step(smooth: np.ndarray, source: str) -> float:
    d = np.linalg.norm(np.diff(smooth, axis=0), axis=1)
    fast = float(np.percentile(d, 90))
    if not fast > 0:
        raise SegmentationError(f"{source}: the tool does not move (all positions equal); no periodic part")
    return float(np.median(d[d > 0.3 * fast]))


def resample_by_distance(points: np.ndarray, step: float) -> np.ndarray:
    """Indices (M,) of the samples kept: the first, then each one at least ``step`` from the last kept."""
    xs, ys, zs = points[:, 0].tolist(), points[:, 1].tolist(), points[:, 2].tolist()
    step2 = step * step
    keep = [0]
    lx, ly, lz = xs[0], ys[0], zs[0]
    for i in range(1, len(xs)):
        dx, dy, dz = xs[i] - lx, ys[i] - ly, zs[i] - lz
        if dx * dx + dy * dy + dz * dz >= step2:
            keep.append(i)
            lx, ly, lz = xs[i], ys[i], zs[i]
    return np.asarray(keep, dtype=int)
