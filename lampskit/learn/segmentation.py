"""Segmentation of a demonstration into periodic and transitional MPs (paper II-A, Procedure 1).

Clusters are *spatial* (board regions wiped again and again), movement
primitives are *time intervals*. :func:`segment` with ``method="optics"``:

1. **Smooth** the positions (Savitzky-Golay, quadratic, :data:`SMOOTH_WINDOW_S`)
   so sensor noise neither adds path length nor fakes motion.
2. **Resample by distance.** Keep a sample whenever the tool has moved at
   least ``step`` from the last kept one; ``step`` is the median distance
   travelled per sample while moving (samples faster than 30 % of the 90th
   speed percentile), scaled up by ``rate / MAX_POINT_RATE_HZ`` for demos
   recorded faster than :data:`MAX_POINT_RATE_HZ` (a hand's motion holds
   nothing finer; a 460 Hz demo would otherwise cost OPTICS 5x more for
   the same answer). The density of kept points then counts *passes over a
   place*, not time spent there: a stroke wiped five times is five times as
   dense as a transition crossing once, and a tool resting before the
   approach (as in the real demonstrations) is one point instead of the
   densest "cluster" of all. Each sample takes the label of the last kept point.
3. **OPTICS** (:mod:`.optics`, ``max_eps = inf``) on the kept points, with
   ``min_samples = round(WINDOW_S * min(rate_hz, MAX_POINT_RATE_HZ))`` unless given: the number of
   points a tool moving at its typical speed leaves in :data:`WINDOW_S`
   seconds (50 at 100 Hz, 100 at 200 Hz; the same path length at any rate,
   since ``step`` scales with the sample period). Along a straight path
   crossed once the reachability is ``(min_samples - 1) / 2 * step``, the
   *single-pass reachability* ``R1``; where a stroke repeats n times it is
   about ``R1 / n``.
4. **Threshold** (automatic unless given): Otsu's threshold on the log
   reachability (the split of the plot into a "valley" and a "peak" class
   with the largest between-class variance, computed exactly over the
   sorted values), clamped to ``[BETA_LO, BETA_HI] * R1`` = [0.4, 0.7] R1.
   The clamp encodes what a valley is whatever the histogram looks like: a
   place passed at least 1 / 0.4 = 2.5 times is always dense, one passed
   fewer than 1 / 0.7 = 1.4 times never is (Otsu alone splits a deep
   zig-zag valley from a shallower circle valley when both are present).
   Valleys below the threshold are clusters (candidate periodic MPs), peaks
   above it are transitional. Clusters are read from the ordering like
   DBSCAN at ``eps = threshold`` (sklearn's ``cluster_optics_dbscan``);
   clusters of fewer than ``min_samples`` points are noise.
5. **Time runs.** Per-sample labels -> runs in time. Two runs of one cluster
   are joined when the tool never leaves the cluster's region in between
   (:data:`STAY_FACTOR`); otherwise they stay two periodic segments (the
   same region wiped twice with an excursion between). Runs shorter than
   ``min_duration_s`` are relabelled, shortest first: a short gap inside a
   cluster joins it, a short cluster run becomes transitional (or joins the
   cluster around it); a short transitional run between two different
   clusters stays (a quick move between adjacent stains).
6. **Boundaries by recurrence.** Spatial clusters also swallow the ends of
   transitions that spiral into and out of a stroke, so each periodic run's
   ends are moved to where the motion stops repeating itself: with the
   run's period ``P`` (autocorrelation peak), the *recurrence* of a sample
   is the distance, in the state ``(position, velocity / omega)`` with
   ``omega = 2 pi / P``, to the path ``P`` (+-15 %) earlier or later. It is
   median-filtered over ``P / 2`` and compared with ``REC_GAMMA`` (2) times
   its median over the run; the segment spans the first to the last
   stretch below that level lasting at least one period, searched from one
   period before to one period after the run. Velocity makes the test
   sensitive early: a smooth (C2) departure from a cycle shows in position
   only as ``t^3`` but in velocity as ``t^2``.
7. **Periodicity check.** A periodic MP covers its area again and again: it
   needs ``path length / extent >= MIN_PATH_RATIO`` (extent = range along
   its first principal axis; a circle gives about pi per cycle, a zig-zag
   about 2, a single sweep 1) and an extent of at least
   :data:`MIN_EXTENT_M`. Rejected candidates become transitional. No
   periodic segment left -> :class:`SegmentationError` naming the reason.

Baselines (paper Fig. 5) ``"kmeans"`` and ``"affinity"`` cluster the same
resampled points (steps 1-2) with sklearn's K-Means (``k`` of the best
silhouette over 2..8, on at most 2000 points, unless given) or Affinity
Propagation (damping 0.9, on at most :data:`AFFINITY_MAX_POINTS` evenly
spaced points; every point then takes its nearest exemplar). They label
every sample with a cluster and know no transitional points: each cluster's
time runs become periodic segments (runs shorter than ``min_duration_s``
join their longer neighbour), with none of steps 5-7, which is what the
figure shows.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import savgol_filter

from lampskit.learn.demo import Demonstration
from lampskit.errors import SegmentationError
from lampskit.learn.optics import OpticsResult, optics

METHODS = ("optics", "kmeans", "affinity")
#: Time window setting the default ``min_samples`` [s].
WINDOW_S = 0.5
#: Resampled points are kept no denser than a demo sampled at this rate would give [Hz].
MAX_POINT_RATE_HZ = 200.0
#: Savitzky-Golay window of the position smoothing [s].
SMOOTH_WINDOW_S = 0.05
#: Default minimum duration of a segment [s].
MIN_DURATION_S = 0.3
#: Automatic threshold clamp, as fractions of the single-pass reachability.
BETA_LO, BETA_HI = 0.4, 0.7
#: A transitional gap stays inside its cluster when no sample is farther from
#: the cluster centre than this many times the cluster's 95th percentile radius.
STAY_FACTOR = 1.5
#: Period search range [s].
MIN_PERIOD_S, MAX_PERIOD_S = 0.2, 5.0
#: Lags compared in the recurrence, as fractions of the period.
LAG_LO, LAG_HI = 0.85, 1.15
#: A sample recurs when its (median-filtered) recurrence is below this many
#: times the run's median recurrence.
REC_GAMMA = 2.0
#: Periodic candidates need path length / extent at least this ...
MIN_PATH_RATIO = 3.0
#: ... and an extent of at least this [m].
MIN_EXTENT_M = 0.005
#: Affinity Propagation runs on at most this many points (it is O(n^2)).
AFFINITY_MAX_POINTS = 800
#: K-Means tries k in this range (inclusive) when not given.
KMEANS_K_RANGE = (2, 8)

ProgressCallback = Callable[[int, int], None]
#: Progress is reported on this scale by :func:`segment`.
PROGRESS_TOTAL = 100

Run = tuple[int, int, int]  # (cluster or -1, start, end)


@dataclass(frozen=True)
class Segment:
    """One movement primitive's samples ``[start, end)``.

    ``kind`` is ``"periodic"`` (``cluster >= 0``: the spatial cluster, shared
    by two visits of one region) or ``"transitional"`` (``cluster == -1``).
    """

    start: int
    end: int
    kind: str
    cluster: int

    def __post_init__(self) -> None:
        if not 0 <= self.start < self.end:
            raise SegmentationError(f"segment needs 0 <= start < end, got [{self.start}, {self.end})")
        if self.kind not in ("periodic", "transitional"):
            raise SegmentationError(f"segment kind must be 'periodic' or 'transitional', got {self.kind!r}")
        if (self.kind == "periodic") != (self.cluster >= 0):
            want = ">= 0" if self.kind == "periodic" else "-1"
            raise SegmentationError(f"a {self.kind} segment needs cluster {want}, got {self.cluster}")

    @property
    def n_samples(self) -> int:
        return self.end - self.start

    def to_dict(self) -> dict:
        return {"start": self.start, "end": self.end, "kind": self.kind, "cluster": self.cluster}


@dataclass(frozen=True)
class SegmentationParams:
    """Settings of :func:`segment` (``None`` = automatic, see the module docstring).

    Attributes
    ----------
    min_samples : int or None
        OPTICS ``min_samples`` (>= 2); default ``round(WINDOW_S * rate_hz)``.
    threshold : float or None
        Reachability threshold [m] (> 0); default Otsu, clamped.
    min_duration_s : float
        Runs shorter than this [s] are relabelled (>= 0).
    min_path_ratio : float
        Periodicity check: path length / extent (>= 1).
    n_clusters : int or None
        K-Means ``k`` (>= 2); default by silhouette.
    """

    min_samples: int | None = None
    threshold: float | None = None
    min_duration_s: float = MIN_DURATION_S
    min_path_ratio: float = MIN_PATH_RATIO
    n_clusters: int | None = None

    def __post_init__(self) -> None:
        if self.min_samples is not None and not _is_int_at_least(self.min_samples, 2):
            raise SegmentationError(f"min_samples must be an int >= 2 or None, got {self.min_samples!r}")
        if self.threshold is not None and not (_is_real(self.threshold) and 0 < self.threshold < np.inf):
            raise SegmentationError(f"threshold must be a finite reachability > 0 m or None, got {self.threshold!r}")
        if not (_is_real(self.min_duration_s) and 0 <= self.min_duration_s < np.inf):
            raise SegmentationError(f"min_duration_s must be a finite duration >= 0 s, got {self.min_duration_s!r}")
        if not (_is_real(self.min_path_ratio) and 1 <= self.min_path_ratio < np.inf):
            raise SegmentationError(f"min_path_ratio must be finite and >= 1, got {self.min_path_ratio!r}")
        if self.n_clusters is not None and not _is_int_at_least(self.n_clusters, 2):
            raise SegmentationError(f"n_clusters must be an int >= 2 or None, got {self.n_clusters!r}")


@dataclass(frozen=True)
class Segmentation:
    """The segments of one demonstration and how they were found.

    Attributes
    ----------
    segments : tuple of Segment
        In time order, covering ``[0, T)`` without gaps or overlaps.
    labels : array of int, shape (T,)
        Cluster of each sample, -1 on transitional samples (agrees with
        ``segments``).
    method : str
        One of :data:`METHODS`.
    threshold : float or None
        Reachability threshold used [m] (None for the baselines).
    min_samples : int or None
        OPTICS ``min_samples`` used (None for the baselines).
    step_m : float
        Distance-resampling step [m].
    point_samples : array of int, shape (M,)
        Sample index of each resampled point (the points clustered).
    optics : OpticsResult or None
        OPTICS of the M resampled points (None for the baselines); its
        ``ordering`` indexes ``point_samples``.
    params : SegmentationParams
        The settings asked for.
    """

    segments: tuple[Segment, ...]
    labels: np.ndarray
    method: str
    threshold: float | None
    min_samples: int | None
    step_m: float
    point_samples: np.ndarray
    optics: OpticsResult | None
    params: SegmentationParams = field(default_factory=SegmentationParams)

    def __post_init__(self) -> None:
        self.labels.setflags(write=False)
        self.point_samples.setflags(write=False)

    @property
    def n_samples(self) -> int:
        return len(self.labels)

    @property
    def periodic_segments(self) -> tuple[Segment, ...]:
        return tuple(s for s in self.segments if s.kind == "periodic")

    @property
    def periodic_mask(self) -> np.ndarray:
        """True on samples of periodic segments, shape (T,)."""
        return self.labels >= 0

    @property
    def ordering_samples(self) -> np.ndarray:
        """Sample index of each OPTICS point in OPTICS order, shape (M,) (empty for baselines)."""
        if self.optics is None:
            return np.zeros(0, dtype=int)
        return self.point_samples[self.optics.ordering]

    @property
    def ordering_labels(self) -> np.ndarray:
        """Final label of each OPTICS point in OPTICS order, shape (M,) (for colouring the plot)."""
        return self.labels[self.ordering_samples]

    @property
    def reachability_plot(self) -> np.ndarray:
        """Reachability in OPTICS order [m], shape (M,) (empty for baselines); the first is inf."""
        if self.optics is None:
            return np.zeros(0)
        return self.optics.reachability[self.optics.ordering]

    def to_dict(self, summary: bool = False) -> dict:
        """JSON-ready: method, threshold [m], min_samples, step_m, n_samples and segments.

        Unless ``summary``, also ``ordering`` (sample index of each OPTICS
        point, in OPTICS order), ``reachability`` [m] in that order (the
        first, infinite, value as None) and the ``params``.
        """
        d = {
            "method": self.method,
            "threshold": self.threshold,
            "min_samples": self.min_samples,
            "step_m": self.step_m,
            "n_samples": self.n_samples,
            "segments": [s.to_dict() for s in self.segments],
        }
        if not summary:
            d["ordering"] = self.ordering_samples.tolist()
            d["reachability"] = [float(r) if np.isfinite(r) else None for r in self.reachability_plot]
            d["params"] = asdict(self.params)
        return d


# --------------------------------------------------------------------------
# public functions


def segment(
    demo: Demonstration,
    method: str = "optics",
    *,
    min_samples: int | None = None,
    threshold: float | None = None,
    min_duration_s: float = MIN_DURATION_S,
    min_path_ratio: float = MIN_PATH_RATIO,
    n_clusters: int | None = None,
    progress: ProgressCallback | None = None,
) -> Segmentation:
    """Segment ``demo`` into periodic and transitional MPs (see the module docstring).

    Parameters
    ----------
    demo : Demonstration
        Positions ``position_m`` (T, 3) [m] at times ``t_s`` (T,) [s].
    method : str
        ``"optics"`` (the paper's method), or a baseline: ``"kmeans"``,
        ``"affinity"``.
    min_samples, threshold, min_duration_s, min_path_ratio, n_clusters
        See :class:`SegmentationParams`; ``min_samples`` and ``threshold``
        apply to OPTICS, ``n_clusters`` to K-Means.
    progress : callable, optional
        Called as ``progress(done, PROGRESS_TOTAL)`` while clustering and
        once with ``done == PROGRESS_TOTAL`` at the end.

    Raises
    ------
    SegmentationError
        Unknown method, bad parameter, a demo that hardly moves, or (OPTICS)
        no periodic part.
    """
    if method not in METHODS:
        raise SegmentationError(f"unknown segmentation method {method!r}; valid: {', '.join(METHODS)}")
    if not isinstance(demo, Demonstration):
        raise SegmentationError(f"segment() needs a Demonstration, got {type(demo).__name__}")
    params = SegmentationParams(min_samples, threshold, min_duration_s, min_path_ratio, n_clusters)
    return _segment_impl(demo, method, params, progress)


def frame_accuracy(segmentation: Segmentation, true_periodic: np.ndarray) -> float:
    """Fraction of samples whose kind (periodic or not) matches the truth.

    Parameters
    ----------
    segmentation : Segmentation
    true_periodic : array of bool, shape (T,)
        True on samples labelled periodic; read here only, never to segment.
    """
    truth = np.asarray(true_periodic)
    if truth.shape != (segmentation.n_samples,):
        raise SegmentationError(f"true_periodic must have shape ({segmentation.n_samples},), got {truth.shape}")
    return float(np.mean(segmentation.periodic_mask == truth.astype(bool)))


def segment_counts(segmentation: Segmentation) -> dict[str, int]:
    """Numbers of ``periodic`` and ``transitional`` segments and of distinct periodic ``clusters``."""
    per = segmentation.periodic_segments
    return {
        "periodic": len(per),
        "transitional": len(segmentation.segments) - len(per),
        "clusters": len({s.cluster for s in per}),
    }


def true_segment_count(true_periodic: np.ndarray) -> int:
    """Number of periodic runs in a label array of shape (T,) (True = periodic)."""
    truth = np.asarray(true_periodic, dtype=bool).astype(int)
    return int(np.sum(np.diff(np.r_[0, truth]) == 1))


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


# --------------------------------------------------------------------------
# the pipeline


def _segment_impl(
    demo: Demonstration, method: str, params: SegmentationParams, progress: ProgressCallback | None
) -> Segmentation:
    t = demo.t_s
    smooth = _smooth(demo.position_m, demo.rate_hz)
    point_rate_hz = min(demo.rate_hz, MAX_POINT_RATE_HZ)
    step = _resampling_step(smooth, demo.source) * demo.rate_hz / point_rate_hz
    keep = _resample_by_distance(smooth, step)
    points = smooth[keep]
    if len(points) < 10:
        raise SegmentationError(
            f"{demo.source}: the tool hardly moves ({len(points)} points {step * 1000:.3g} mm apart, "
            "need at least 10); no periodic part"
        )
    cluster_progress = _scaled(progress, 0, 90)
    result = eps = ms = None
    if method == "optics":
        ms = params.min_samples if params.min_samples is not None else int(round(WINDOW_S * point_rate_hz))
        ms = int(min(max(ms, 2), len(points)))
        result = optics(points, ms, progress=cluster_progress)
        if params.threshold is not None:
            eps = float(params.threshold)
        else:
            eps = reachability_threshold(result.reachability[result.ordering], ms, step)
        point_labels = dbscan_labels(result, eps)
        sizes = np.bincount(point_labels[point_labels >= 0], minlength=1)
        small = (point_labels >= 0) & (sizes[np.maximum(point_labels, 0)] < ms)
        point_labels[small] = -1
    elif method == "kmeans":
        point_labels = _kmeans_labels(points, params.n_clusters, cluster_progress)
    else:
        point_labels = _affinity_labels(points, cluster_progress)
    # each sample takes the label of the last kept point at or before it
    runs = _runs(point_labels[np.searchsorted(keep, np.arange(len(t)), side="right") - 1])
    if method == "optics":
        runs = _bridge_stays(runs, smooth)
        runs = _merge_short_runs(runs, t, params.min_duration_s, transitions=True)
        runs = _refine_boundaries(runs, smooth, demo.rate_hz)
        runs = _merge_short_runs(runs, t, params.min_duration_s, transitions=True)
        runs, rejected = _check_periodic(runs, smooth, params.min_path_ratio)
        if not any(c >= 0 for c, _, _ in runs):
            raise SegmentationError(_no_periodic_message(demo, eps, ms, rejected, params.min_path_ratio))
    else:
        runs = _merge_short_runs(runs, t, params.min_duration_s, transitions=False)
    runs = _renumber(runs)
    segments = tuple(Segment(a, b, "periodic" if c >= 0 else "transitional", c) for c, a, b in runs)
    labels = np.empty(len(t), dtype=int)
    for c, a, b in runs:
        labels[a:b] = c
    if progress is not None:
        progress(PROGRESS_TOTAL, PROGRESS_TOTAL)
    return Segmentation(segments, labels, method, eps, ms, step, keep, result, params)


def _scaled(progress: ProgressCallback | None, lo: int, hi: int) -> ProgressCallback | None:
    if progress is None:
        return None
    return lambda done, total: progress(lo + (hi - lo) * done // max(total, 1), PROGRESS_TOTAL)


def _smooth(position_m: np.ndarray, rate_hz: float, deriv: int = 0) -> np.ndarray:
    """Savitzky-Golay smoothed positions [m] (or velocities [m/s] with ``deriv=1``), shape (T, 3)."""
    n = len(position_m)
    win = min(max(int(round(SMOOTH_WINDOW_S * rate_hz)) | 1, 5), n if n % 2 else n - 1)
    return savgol_filter(position_m, win, 2, deriv=deriv, delta=1.0 / rate_hz, axis=0, mode="interp")


def _resampling_step(smooth: np.ndarray, source: str) -> float:
    d = np.linalg.norm(np.diff(smooth, axis=0), axis=1)
    fast = float(np.percentile(d, 90))
    if not fast > 0:
        raise SegmentationError(f"{source}: the tool does not move (all positions equal); no periodic part")
    return float(np.median(d[d > 0.3 * fast]))


def _resample_by_distance(points: np.ndarray, step: float) -> np.ndarray:
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


# --------------------------------------------------------------------------
# runs in time


def _runs(labels: np.ndarray) -> list[Run]:
    """Runs of equal labels (T,) as ``(label, start, end)``."""
    edges = np.flatnonzero(np.diff(labels)) + 1
    starts = np.r_[0, edges]
    ends = np.r_[edges, len(labels)]
    return [(int(labels[a]), int(a), int(b)) for a, b in zip(starts, ends)]


def _join(runs: list[Run]) -> list[Run]:
    out: list[Run] = []
    for c, a, b in runs:
        if out and out[-1][0] == c:
            out[-1] = (c, out[-1][1], b)
        else:
            out.append((c, a, b))
    return out


def _bridge_stays(runs: list[Run], smooth: np.ndarray) -> list[Run]:
    """Join two runs of one cluster when the transitional run between them stays in the cluster's region."""
    out = list(runs)
    i = 1
    while i + 1 < len(out):
        (c0, a0, b0), (c, a, b), (c1, a1, b1) = out[i - 1], out[i], out[i + 1]
        if c == -1 and c0 >= 0 and c0 == c1:
            pts = np.vstack([smooth[a0:b0], smooth[a1:b1]])
            centre = pts.mean(axis=0)
            radius = float(np.percentile(np.linalg.norm(pts - centre, axis=1), 95))
            if np.max(np.linalg.norm(smooth[a:b] - centre, axis=1)) <= STAY_FACTOR * radius:
                out[i - 1 : i + 2] = [(c0, a0, b1)]
                continue
        i += 1
    return out


def _merge_short_runs(runs: list[Run], t_s: np.ndarray, min_duration_s: float, transitions: bool) -> list[Run]:
    """Relabel runs shorter than ``min_duration_s``, shortest first.

    With ``transitions`` (OPTICS) a short cluster run becomes transitional
    unless one cluster surrounds it, and a short transitional run joins a
    cluster only when that cluster is on both sides or it lies at an end of
    the demo. Without (baselines) a short run joins its longer neighbour.
    """
    period = float(t_s[1] - t_s[0]) if len(t_s) > 1 else 0.0

    def duration(r: Run) -> float:
        return float(t_s[r[2] - 1] - t_s[r[1]]) + period

    runs = _join(runs)
    kept: set[int] = set()  # starts of short runs that stay as they are
    while len(runs) > 1:
        short = [(duration(r), i) for i, r in enumerate(runs) if r[1] not in kept and duration(r) < min_duration_s]
        if not short:
            break
        i = min(short)[1]
        c, a, _ = runs[i]
        left = runs[i - 1][0] if i > 0 else None
        right = runs[i + 1][0] if i + 1 < len(runs) else None
        if not transitions:
            if left is None or right is None:
                new = right if left is None else left
            else:
                new = left if duration(runs[i - 1]) >= duration(runs[i + 1]) else right
        elif c >= 0:
            new = left if left is not None and left == right else -1
        elif left is None or right is None:
            new = right if left is None else left
        else:
            new = left if left == right else c
        if new == c:
            kept.add(a)
            continue
        runs[i] = (new, runs[i][1], runs[i][2])
        runs = _join(runs)
        kept = {r[1] for r in runs} & kept
    return runs


# --------------------------------------------------------------------------
# boundaries by recurrence


def _period_samples(points: np.ndarray, rate_hz: float) -> int | None:
    """Dominant period [samples] of ``points`` (K, d): the autocorrelation peak after its first zero."""
    x = points - points.mean(axis=0)
    n = len(x)
    lo = int(MIN_PERIOD_S * rate_hz)
    hi = min(n // 2, int(MAX_PERIOD_S * rate_hz))
    if hi <= lo + 2:
        return None
    f = np.fft.rfft(x, 2 * n, axis=0)
    ac = np.fft.irfft(np.sum(np.abs(f) ** 2, axis=1), 2 * n)[:n] / (n - np.arange(n))
    below = np.flatnonzero(ac[:hi] < 0)
    if below.size == 0 or max(lo, int(below[0])) >= hi:
        return None
    start = max(lo, int(below[0]))
    return start + int(np.argmax(ac[start:hi]))


def _recurrence(state: np.ndarray, period: int) -> np.ndarray:
    """Distance from each state (K, d) to the path ``period`` (+-15 %) samples before or after it, shape (K,).

    The path is the polyline through the states, so the distance does not
    depend on where the samples happen to fall on it; inf where no lag fits.
    """
    n = len(state)
    rec = np.full(n, np.inf)
    seg = np.diff(state, axis=0)  # segment j runs from state j to j + 1
    seg_len2 = np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-300)
    for lag in range(max(1, int(LAG_LO * period)), min(n - 1, int(np.ceil(LAG_HI * period))) + 1):
        # state i against segment (i - lag, i - lag + 1), and against (i + lag - 1, i + lag)
        for p_sl, s_sl in ((slice(lag, n), slice(0, n - lag)), (slice(0, n - lag), slice(lag - 1, n - 1))):
            rel = state[p_sl] - state[s_sl]
            u = np.clip(np.einsum("ij,ij->i", rel, seg[s_sl]) / seg_len2[s_sl], 0.0, 1.0)
            d = np.linalg.norm(rel - u[:, None] * seg[s_sl], axis=1)
            np.minimum(rec[p_sl], d, out=rec[p_sl])
    return rec


def _refine_boundaries(runs: list[Run], smooth: np.ndarray, rate_hz: float) -> list[Run]:
    """Move each periodic run's ends to where the motion stops recurring (step 6 of the module docstring)."""
    n = len(smooth)
    velocity = _smooth(smooth, rate_hz, deriv=1)
    labels = np.full(n, -1)
    per = [r for r in runs if r[0] >= 0]
    for j, (c, a, b) in enumerate(per):
        labels[a:b] = c
        period = _period_samples(smooth[a:b], rate_hz)
        if period is None:
            continue
        lo = max(per[j - 1][2] if j > 0 else 0, a - period)
        hi = min(per[j + 1][1] if j + 1 < len(per) else n, b + period)
        omega = 2 * np.pi * rate_hz / period
        rec = _recurrence(np.hstack([smooth[lo:hi], velocity[lo:hi] / omega]), period)
        finite = np.isfinite(rec)
        if not finite[a - lo : b - lo].any():
            continue
        rec[~finite] = np.max(rec[finite])
        rec = median_filter(rec, size=max(1, period // 2) | 1, mode="nearest")
        level = REC_GAMMA * float(np.median(rec[a - lo : b - lo]))
        stretches = [(s0, s1) for v, s0, s1 in _runs((rec < level).astype(int)) if v == 1 and s1 - s0 >= period]
        if stretches:
            labels[a:b] = -1
            labels[lo + stretches[0][0] : lo + stretches[-1][1]] = c
    return _runs(labels)


# --------------------------------------------------------------------------
# periodicity check


def _extent_and_ratio(points: np.ndarray) -> tuple[float, float]:
    """Range [m] along the first principal axis of ``points`` (K, 3), and path length / that range."""
    if len(points) < 3:
        return 0.0, 0.0
    path = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    proj = centred @ vt[0]
    extent = float(proj.max() - proj.min())
    return extent, (path / extent if extent > 0 else 0.0)


def _check_periodic(runs: list[Run], smooth: np.ndarray, min_ratio: float) -> tuple[list[Run], list[tuple[int, int, str]]]:
    out: list[Run] = []
    rejected: list[tuple[int, int, str]] = []
    for c, a, b in runs:
        if c >= 0:
            extent, ratio = _extent_and_ratio(smooth[a:b])
            if extent < MIN_EXTENT_M:
                rejected.append((a, b, f"extent {extent * 1000:.2g} mm < {MIN_EXTENT_M * 1000:g} mm"))
                c = -1
            elif ratio < min_ratio:
                rejected.append((a, b, f"path length / extent {ratio:.2f} < {min_ratio:g}"))
                c = -1
        out.append((c, a, b))
    return _join(out), rejected


def _renumber(runs: list[Run]) -> list[Run]:
    """Cluster ids 0, 1, ... in order of first appearance."""
    ids: dict[int, int] = {}
    return [((ids.setdefault(c, len(ids)) if c >= 0 else -1), a, b) for c, a, b in runs]


def _no_periodic_message(
    demo: Demonstration, eps: float, ms: int, rejected: list[tuple[int, int, str]], min_ratio: float
) -> str:
    msg = f"{demo.source}: no periodic part found (OPTICS min_samples={ms}, threshold={eps:.4g} m)"
    if rejected:
        detail = "; ".join(f"samples {a}-{b}: {why}" for a, b, why in rejected[:3])
        more = f" and {len(rejected) - 3} more" if len(rejected) > 3 else ""
        return f"{msg}: {len(rejected)} dense region(s) rejected as not periodic ({detail}{more})"
    return f"{msg}: no region of the path is passed over densely enough for long enough"


# --------------------------------------------------------------------------
# baselines


def _kmeans_labels(points: np.ndarray, n_clusters: int | None, progress: ProgressCallback | None) -> np.ndarray:
    from sklearn.cluster import KMeans
    from sklearn.metrics import silhouette_score

    if n_clusters is not None:
        if n_clusters > len(points):
            raise SegmentationError(f"n_clusters must be <= the {len(points)} resampled points, got {n_clusters}")
        return KMeans(n_clusters, n_init=4, random_state=0).fit_predict(points)
    lo, hi = KMEANS_K_RANGE
    ks = list(range(lo, min(hi, len(points) - 1) + 1))
    sub = points[:: max(1, len(points) // 2000)]
    best: tuple[float, np.ndarray] | None = None
    for j, k in enumerate(ks):
        km = KMeans(k, n_init=4, random_state=0).fit(points)
        sub_labels = km.predict(sub)
        score = silhouette_score(sub, sub_labels) if len(set(sub_labels.tolist())) > 1 else -1.0
        if best is None or score > best[0]:
            best = (score, km.labels_)
        if progress is not None:
            progress(j + 1, len(ks))
    return best[1]


def _affinity_labels(points: np.ndarray, progress: ProgressCallback | None) -> np.ndarray:
    from sklearn.cluster import AffinityPropagation
    from sklearn.exceptions import ConvergenceWarning

    sub = points[:: max(1, int(np.ceil(len(points) / AFFINITY_MAX_POINTS)))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        centres = AffinityPropagation(damping=0.9, max_iter=1000, random_state=0).fit(sub).cluster_centers_
    if len(centres) == 0:
        raise SegmentationError(f"Affinity Propagation found no exemplars in {len(sub)} points (did not converge)")
    if progress is not None:
        progress(1, 1)
    d2 = np.sum((points[:, None, :] - centres[None, :, :]) ** 2, axis=2)
    return np.argmin(d2, axis=1)


def _is_int_at_least(value: object, low: int) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= low


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
