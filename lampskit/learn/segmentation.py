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
   same region wiped twice with an excursion between). Before that, clusters
   that take turns within one continuous stroke (one seen again after runs
   each shorter than half the slowest period, gaps shorter than
   ``min_duration_s``) are united: with the threshold set by the densest
   spot of a long take, one stroke can fall apart into two. Runs shorter than
   ``min_duration_s`` are relabelled, shortest first: a short gap inside a
   cluster joins it, a short cluster run becomes transitional (or joins the
   cluster around it); a short transitional run between two different
   clusters stays (a quick move between adjacent stains).
5b. **Hops** (:mod:`.lifts`): a periodic run is cut where the pad leaves its surface between two wipes
   (above the run's contact band for 0.3 s or more, inside the run, not repeating the strokes around it):
   the lifted stretch is transitional.
6. **Boundaries by recurrence.** Spatial clusters also swallow the ends of
   transitions that spiral into and out of a stroke, so each periodic run's
   ends are moved to where the motion stops repeating itself: with the
   run's period ``P`` (the first autocorrelation peak of the velocity
   within 0.8 of the highest: velocity weighs the strokes over a slow
   lift-off, and a run holding two wipes of one spot also correlates at
   the lag between them), the *recurrence* of a sample
   is the distance, in the state ``(position, velocity / omega)`` with
   ``omega = 2 pi / P``, to the path ``P`` (+-15 %) earlier or later. It is
   median-filtered over ``P / 2`` and compared with ``REC_GAMMA`` (2) times
   its median over the run; the segment spans the first to the last
   stretch below that level lasting at least one period, searched from one
   period before to one period after the run; the start then moves back
   while the recurrence stays below ``REC_GAMMA_LOOSE`` (3) times the median
   (hysteresis: a person's first strokes are ragged and recur less exactly), and on over the touch-down and
   press before the first stroke while the tool stays on the strokes' fitted plane, inside their footprint
   and slower than half their median speed (``time_runs.settle_start``). A sample slower than
   ``REST_SPEED_SHARE`` (0.1) of the run's median speed is at rest: it is taken out before the recurrence
   is computed (the stroke after a pause is compared with the strokes before it) and counts as not
   recurring. Two recurring stretches with motion between them that does not recur (a slow stroke, a
   pause, a grip shift; or a lift-off, a hop, a slide to another patch) are one wiping phase unless the
   evidence of :mod:`.phase_continuity` cuts: a lift off the surface both sides' strokes span, a jump of
   the stroke centre beyond their reach and drift, a change of stroke period, a long rest; each cut has
   a margin (docs/method.md). Velocity makes the test
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
figure shows. ``"sklearn-optics"`` is plain scikit-learn OPTICS on the same
points read at a fixed threshold (:data:`FIXED_THRESHOLD_M`, 40 mm, the
bundled demo's automatic one, unless given): noise is transitional, short
runs are relabelled as in step 5, and none of steps 5-7's other parts run.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from lampskit.errors import SegmentationError
from lampskit.learn.cluster_baselines import FIXED_THRESHOLD_M, affinity_labels, kmeans_labels, sklearn_optics_labels
from lampskit.learn.cut_margins import cut_margins
from lampskit.learn.demo import Demonstration
from lampskit.learn.lifts import split_at_lifts
from lampskit.learn.optics import OpticsResult, ProgressCallback, optics
from lampskit.learn.reachability import (
    dbscan_labels,
    reachability_threshold,
    resample_by_distance,
    resampling_step,
    smooth_positions,
)
from lampskit.learn.time_runs import (
    bridge_stays,
    check_periodic,
    join_runs,
    merge_short_runs,
    refine_boundaries,
    renumber,
    runs_from_labels,
    unite_alternating,
)

METHODS = ("optics", "kmeans", "affinity", "sklearn-optics")
#: Time window setting the default ``min_samples`` [s].
WINDOW_S = 0.5
#: Resampled points are kept no denser than a demo sampled at this rate would give [Hz].
MAX_POINT_RATE_HZ = 200.0
#: Default minimum duration of a segment [s].
MIN_DURATION_S = 0.3
#: Periodic candidates need path length / extent at least this ...
MIN_PATH_RATIO = 3.0

#: Progress is reported on this scale by :func:`segment`.
PROGRESS_TOTAL = 100


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
    cuts : tuple of dict
        How sure each boundary is (:func:`~.cut_margins.cut_margins`): ``margin`` > 0 the cut is made by that
        much, near 0 check it.
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
    cuts: tuple = ()

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
        first, infinite, value as None), the ``params`` and the ``cuts``.
        """
        d: dict[str, Any] = {
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
            d["cuts"] = list(self.cuts)
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
        ``"affinity"``, ``"sklearn-optics"`` (scikit-learn's OPTICS cut at a
        fixed ``threshold``, default :data:`~.cluster_baselines.FIXED_THRESHOLD_M`;
        noise transitional, none of steps 5-7).
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


# --------------------------------------------------------------------------
# the pipeline


def _segment_impl(
    demo: Demonstration, method: str, params: SegmentationParams, progress: ProgressCallback | None
) -> Segmentation:
    t = demo.t_s
    smooth = smooth_positions(demo.position_m, demo.rate_hz)
    point_rate_hz = min(demo.rate_hz, MAX_POINT_RATE_HZ)
    step = resampling_step(smooth, demo.source) * demo.rate_hz / point_rate_hz
    keep = resample_by_distance(smooth, step)
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
        point_labels = kmeans_labels(points, params.n_clusters, cluster_progress)
    elif method == "affinity":
        point_labels = affinity_labels(points, cluster_progress)
    else:
        ms = params.min_samples if params.min_samples is not None else int(round(WINDOW_S * point_rate_hz))
        ms = int(min(max(ms, 2), len(points)))
        eps = float(params.threshold) if params.threshold is not None else FIXED_THRESHOLD_M
        point_labels = sklearn_optics_labels(points, ms, eps, cluster_progress)
    # each sample takes the label of the last kept point at or before it
    runs = runs_from_labels(point_labels[np.searchsorted(keep, np.arange(len(t)), side="right") - 1])
    if method == "optics":
        runs = unite_alternating(runs, t, params.min_duration_s)
        runs = bridge_stays(runs, smooth)
        runs = merge_short_runs(runs, t, params.min_duration_s, transitions=True)
        runs = _on_thinned(split_at_lifts, runs, smooth, demo.rate_hz, len(t))
        runs = _on_thinned(refine_boundaries, runs, smooth, demo.rate_hz, len(t))
        runs = merge_short_runs(runs, t, params.min_duration_s, transitions=True)
        runs, rejected = check_periodic(runs, smooth, params.min_path_ratio)
        if not any(c >= 0 for c, _, _ in runs):
            assert eps is not None and ms is not None  # the OPTICS branch set both
            raise SegmentationError(_no_periodic_message(demo, eps, ms, rejected, params.min_path_ratio))
    elif method == "sklearn-optics":  # noise is transitional; none of steps 5-7
        runs = merge_short_runs(runs, t, params.min_duration_s, transitions=True)
    else:
        runs = merge_short_runs(runs, t, params.min_duration_s, transitions=False)
    runs = renumber(runs)
    segments = tuple(Segment(a, b, "periodic" if c >= 0 else "transitional", c) for c, a, b in runs)
    labels = np.empty(len(t), dtype=int)
    for c, a, b in runs:
        labels[a:b] = c
    cuts = cut_margins(smooth, demo.rate_hz, t, [(s.kind, s.start, s.end) for s in segments], keep,
                       None if result is None else result.reachability, eps)
    if progress is not None:
        progress(PROGRESS_TOTAL, PROGRESS_TOTAL)
    return Segmentation(segments, labels, method, eps, ms, step, keep, result, params, tuple(cuts))


def _on_thinned(step, runs: list, smooth: np.ndarray, rate_hz: float, n: int) -> list:
    """Steps 5b and 6 (``step(runs, smooth, rate_hz)``) on every q-th sample of a recording faster than
    :data:`MAX_POINT_RATE_HZ` (q = ceil(rate / 200)): the recurrence compares each sample with a period of lags,
    so its cost grows with the rate squared; a hand's strokes hold nothing finer than 200 Hz. Boundaries come
    back to the full rate (within q samples)."""
    q = max(1, int(np.ceil(rate_hz / MAX_POINT_RATE_HZ - 1e-9)))
    if q == 1:
        return step(runs, smooth, rate_hz)
    m = (n + q - 1) // q
    thin = [(c, a // q, max(a // q + 1, min(-(-b // q), m))) for c, a, b in runs]
    refined = step(join_runs(thin), smooth[::q], rate_hz / q)
    labels = np.full(n, -1)
    for c, a, b in refined:
        labels[a * q:min(b * q, n)] = c
    return runs_from_labels(labels)


def _scaled(progress: ProgressCallback | None, lo: int, hi: int) -> ProgressCallback | None:
    if progress is None:
        return None
    return lambda done, total: progress(lo + (hi - lo) * done // max(total, 1), PROGRESS_TOTAL)


# --------------------------------------------------------------------------
# runs in time


# --------------------------------------------------------------------------
# boundaries by recurrence


# --------------------------------------------------------------------------
# periodicity check


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


def _is_int_at_least(value: object, low: int) -> bool:
    return bool(isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= low)


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
