"""Steps 5-7 of the segmentation: per-sample labels into time runs, their boundaries, the periodicity check.

A run is ``(cluster or -1, start, end)`` over sample indices (end
exclusive); -1 is transitional. :mod:`lampskit.learn.segmentation` explains
each step: runs of one cluster joined where the tool stays in its region,
short runs relabelled, periodic runs' ends moved to where the motion stops
recurring, and candidates that do not cover their area repeatedly rejected.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

from lampskit.learn.phase_continuity import gap_evidence
from lampskit.learn.reachability import smooth_positions

Run = tuple[int, int, int]  # (cluster or -1, start, end)
#: A transitional gap stays inside its cluster when no sample is farther from
#: the cluster centre than this many times the cluster's 95th percentile radius.
STAY_FACTOR = 1.5
#: Period search range [s].
MIN_PERIOD_S, MAX_PERIOD_S = 0.2, 5.0
#: An autocorrelation peak this close to the highest one is the period when it comes first.
PEAK_SHARE = 0.8
#: Lags compared in the recurrence, as fractions of the period.
LAG_LO, LAG_HI = 0.85, 1.15
#: A sample recurs when its (median-filtered) recurrence is below this many
#: times the run's median recurrence.
REC_GAMMA = 2.0
#: ... and the recurring span extends back from its first stretch while below this many times it.
REC_GAMMA_LOOSE = 3.0
#: ... and an extent of at least this [m].
MIN_EXTENT_M = 0.005
#: A sample slower than this share of its run's median speed is at rest: a resting tool repeats itself
#: trivially, but a pause is no stroke.
REST_SPEED_SHARE = 0.1
#: A wipe starts where the tool settles onto the wiped surface, before its strokes recur: the start moves back
#: while the tool stays within the band of heights above the plane fitted to the recurring strokes and within
#: their footprint on it (both the :data:`SURFACE_QUANTILE` of the strokes' own spread, times
#: :data:`SURFACE_MARGIN`), moving slowly. A person touches down, presses and only then strokes; an approach is
#: off the surface, a move arriving along the board comes at stroke speed.
SURFACE_QUANTILE = 0.95
SURFACE_MARGIN = 1.2
#: ... with a floor on the height band [m] (sensor noise on a flat, well-fitted stroke).
SURFACE_BAND_MIN_M = 0.005
#: ... and while the tool is slower than this share of the strokes' median speed (settling, pressing).
SETTLE_SPEED_SHARE = 0.5


def runs_from_labels(labels: np.ndarray) -> list[Run]:
    """Runs of equal labels (T,) as ``(label, start, end)``."""
    edges = np.flatnonzero(np.diff(labels)) + 1
    starts = np.r_[0, edges]
    ends = np.r_[edges, len(labels)]
    return [(int(labels[a]), int(a), int(b)) for a, b in zip(starts, ends)]


def join_runs(runs: list[Run]) -> list[Run]:
    out: list[Run] = []
    for c, a, b in runs:
        if out and out[-1][0] == c:
            out[-1] = (c, out[-1][1], b)
        else:
            out.append((c, a, b))
    return out


#: Clusters that take turns within one continuous motion are one: a run between two visits of a cluster, in a
#: chain of periodic runs with gaps shorter than the minimum duration, is at most this long [s] (half of the
#: slowest stroke period).
ALTERNATION_MAX_S = 2.5


def unite_alternating(runs: list[Run], t_s: np.ndarray, min_duration_s: float) -> list[Run]:
    """Merge clusters that alternate within one continuous stroke (module docstring of segmentation, step 5).

    With the threshold set by the densest spots of a long take, one elongated or shifted stroke can fall apart
    into two or three spatial clusters visited in turn every half cycle (A B A B ...). In a chain of periodic
    runs joined by transitional gaps shorter than ``min_duration_s``, a cluster seen again after runs that are
    each shorter than :data:`ALTERNATION_MAX_S` is one region with everything seen in between: those clusters
    are united everywhere (union-find). Wipes of different spots, with a real transition between them or a
    whole wipe in between, are left apart.
    """
    parent: dict[int, int] = {}

    def find(c: int) -> int:
        while parent.get(c, c) != c:
            c = parent[c]
        return c

    chain: list[Run] = []

    def close_chain() -> None:
        last_seen: dict[int, int] = {}
        for i, (c, _a, _b) in enumerate(chain):
            j = last_seen.get(find(c))
            if j is not None and all(t_s[min(bb, len(t_s) - 1)] - t_s[aa] <= ALTERNATION_MAX_S
                                     for _, aa, bb in chain[j + 1:i]):
                for cc, _, _ in chain[j + 1:i]:
                    ra, rb = find(c), find(cc)
                    if ra != rb:
                        parent[max(ra, rb)] = min(ra, rb)
            last_seen[find(c)] = i
        chain.clear()

    for k, (c, a, b) in enumerate(runs):
        if c >= 0:
            chain.append((c, a, b))
        elif t_s[min(b, len(t_s) - 1)] - t_s[a] >= min_duration_s or k in (0, len(runs) - 1):
            close_chain()
    close_chain()
    if not parent:
        return runs
    return join_runs([(find(c) if c >= 0 else c, a, b) for c, a, b in runs])


def bridge_stays(runs: list[Run], smooth: np.ndarray) -> list[Run]:
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


def merge_short_runs(runs: list[Run], t_s: np.ndarray, min_duration_s: float, transitions: bool) -> list[Run]:
    """Relabel runs shorter than ``min_duration_s``, shortest first.

    With ``transitions`` (OPTICS) a short cluster run becomes transitional
    unless one cluster surrounds it, and a short transitional run joins a
    cluster only when that cluster is on both sides or it lies at an end of
    the demo. Without (baselines) a short run joins its longer neighbour.
    """
    period = float(t_s[1] - t_s[0]) if len(t_s) > 1 else 0.0

    def duration(r: Run) -> float:
        return float(t_s[r[2] - 1] - t_s[r[1]]) + period

    runs = join_runs(runs)
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
        assert new is not None  # (more than one run: a neighbour on one side at least)
        runs[i] = (new, runs[i][1], runs[i][2])
        runs = join_runs(runs)
        kept = {r[1] for r in runs} & kept
    return runs


def period_samples(points: np.ndarray, rate_hz: float) -> int | None:
    """Dominant period [samples] of ``points`` (K, d): the first autocorrelation peak after its first zero that
    reaches :data:`PEAK_SHARE` of the highest (a run holding two wipes of one spot also correlates with itself
    at the lag between them; the stroke's period is the first strong peak, as in pitch detection)."""
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
    window = ac[start:hi]
    best = float(np.max(window))
    peaks = np.flatnonzero((window[1:-1] >= window[:-2]) & (window[1:-1] >= window[2:]) &
                           (window[1:-1] >= PEAK_SHARE * best)) + 1
    return start + (int(peaks[0]) if peaks.size else int(np.argmax(window)))


def recurrence(state: np.ndarray, period: int) -> np.ndarray:
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


def recurrence_across_rests(state: np.ndarray, rest: np.ndarray, period: int) -> np.ndarray:
    """:func:`recurrence` of the states (K, d) with the samples at rest (``rest``, (K,) bool) taken out, so a
    stroke after a pause is compared with the strokes before it (the stroke phase goes on where it stopped);
    inf on the rest samples, shape (K,)."""
    rec = np.full(len(state), np.inf)
    moving = np.flatnonzero(~rest)
    if len(moving) > 1:
        rec[moving] = recurrence(state[moving], period)
    return rec


def refine_boundaries(runs: list[Run], smooth: np.ndarray, rate_hz: float) -> list[Run]:
    """Move each periodic run's ends to where the motion stops recurring (step 6 of the module docstring)."""
    n = len(smooth)
    velocity = smooth_positions(smooth, rate_hz, deriv=1)
    labels = np.full(n, -1)
    per = [r for r in runs if r[0] >= 0]
    for j, (c, a, b) in enumerate(per):
        labels[a:b] = c
        period = period_samples(velocity[a:b], rate_hz)
        if period is None:
            continue
        lo = max(per[j - 1][2] if j > 0 else 0, a - period)
        hi = min(per[j + 1][1] if j + 1 < len(per) else n, b + period)
        omega = 2 * np.pi * rate_hz / period
        speed = np.linalg.norm(velocity[lo:hi], axis=1)
        rest = speed < REST_SPEED_SHARE * float(np.median(speed[a - lo:b - lo]))
        rec = recurrence_across_rests(np.hstack([smooth[lo:hi], velocity[lo:hi] / omega]), rest, period)
        finite = np.isfinite(rec)
        if not finite[a - lo : b - lo].any():
            continue
        rec[~finite] = np.max(rec[finite])
        rec[rest] = np.max(rec)
        rec = median_filter(rec, size=max(1, period // 2) | 1, mode="nearest")
        level = REC_GAMMA * float(np.median(rec[a - lo : b - lo]))
        stretches = [(s0, s1) for v, s0, s1 in runs_from_labels((rec < level).astype(int))
                     if v == 1 and s1 - s0 >= period]
        if stretches:
            labels[a:b] = -1
            loose = rec < REC_GAMMA_LOOSE / REC_GAMMA * level
            floor = 0

            def same_phase(before: tuple[int, int], after: tuple[int, int]) -> bool:
                # same_phase is called within this iteration only (by _wiping_phases below)
                sides = (period_samples(velocity[lo + before[0]:lo + before[1]], rate_hz),  # noqa: B023
                         period_samples(velocity[lo + after[0]:lo + after[1]], rate_hz))  # noqa: B023
                return not gap_evidence(smooth[lo:hi], rest, before, after, period, rate_hz, sides).cuts  # noqa: B023

            for s0, s1 in _wiping_phases(stretches, same_phase):
                # hysteresis at the start: back from the first recurring stretch while below the looser level (a
                # person's first strokes are ragged: they recur, less exactly; the end needs none)
                while s0 > floor and loose[s0 - 1]:
                    s0 -= 1
                s0 = settle_start(smooth[lo:hi], speed, s0, s1, floor)
                labels[lo + s0 : lo + s1] = c
                floor = s1
    return runs_from_labels(labels)


def settle_start(points: np.ndarray, speed: np.ndarray, s0: int, s1: int, floor: int) -> int:
    """Index where the tool settled onto the surface of the strokes ``points[s0:s1]``, at most ``s0``.

    Parameters
    ----------
    points : array, shape (K, 3)
        Smoothed tool positions [m], any frame.
    speed : array, shape (K,)
        Tool speed [m/s] at those samples.
    s0, s1 : int
        The recurring strokes' span in ``points``.
    floor : int
        The start never moves before this index (the end of the previous wiping phase).

    The plane is the least-squares plane of the strokes. The start moves back while the tool is on it
    (``|height| <= band``), inside the strokes' footprint (``in-plane distance to their centre <= reach``)
    and slower than :data:`SETTLE_SPEED_SHARE` of their median speed: touching down and pressing before the
    first stroke, which is part of the wipe; a move that arrives along the board at stroke speed is not.
    """
    strokes = points[s0:s1]
    if s0 <= floor or len(strokes) < 3:
        return s0
    centre = strokes.mean(axis=0)
    _, _, vt = np.linalg.svd(strokes - centre, full_matrices=False)
    normal = vt[2]

    def height_and_reach(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rel = p - centre
        h = rel @ normal
        return np.abs(h), np.linalg.norm(rel - h[:, None] * normal, axis=1)

    h, r = height_and_reach(strokes)
    band = max(SURFACE_BAND_MIN_M, SURFACE_MARGIN * float(np.quantile(h, SURFACE_QUANTILE)))
    reach = SURFACE_MARGIN * float(np.quantile(r, SURFACE_QUANTILE))
    slow = SETTLE_SPEED_SHARE * float(np.median(speed[s0:s1]))
    h, r = height_and_reach(points[floor:s0])
    off = np.flatnonzero((h > band) | (r > reach) | (speed[floor:s0] > slow))
    return floor + (int(off[-1]) + 1 if off.size else 0)


def _wiping_phases(stretches: list[tuple[int, int]], same_phase) -> list[tuple[int, int]]:
    """Recurring stretches ``(start, end)`` in time order grouped into wiping phases: the motion between two that
    does not recur separates them unless ``same_phase(before, after)`` (:mod:`.phase_continuity`: the tool stays
    on the strokes' surface and patch, at their frequency, without a long rest)."""
    phases = [stretches[0]]
    for s0, s1 in stretches[1:]:
        if not same_phase(phases[-1], (s0, s1)):
            phases.append((s0, s1))
        else:
            phases[-1] = (phases[-1][0], s1)
    return phases


def extent_and_ratio(points: np.ndarray) -> tuple[float, float]:
    """Range [m] along the first principal axis of ``points`` (K, 3), and path length / that range."""
    if len(points) < 3:
        return 0.0, 0.0
    path = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    centred = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    proj = centred @ vt[0]
    extent = float(proj.max() - proj.min())
    return extent, (path / extent if extent > 0 else 0.0)


def check_periodic(runs: list[Run], smooth: np.ndarray,
                   min_ratio: float) -> tuple[list[Run], list[tuple[int, int, str]]]:
    out: list[Run] = []
    rejected: list[tuple[int, int, str]] = []
    for c, a, b in runs:
        if c >= 0:
            extent, ratio = extent_and_ratio(smooth[a:b])
            if extent < MIN_EXTENT_M:
                rejected.append((a, b, f"extent {extent * 1000:.2g} mm < {MIN_EXTENT_M * 1000:g} mm"))
                c = -1
            elif ratio < min_ratio:
                rejected.append((a, b, f"path length / extent {ratio:.2f} < {min_ratio:g}"))
                c = -1
        out.append((c, a, b))
    return join_runs(out), rejected


def renumber(runs: list[Run]) -> list[Run]:
    """Cluster ids 0, 1, ... in order of first appearance."""
    ids: dict[int, int] = {}
    return [((ids.setdefault(c, len(ids)) if c >= 0 else -1), a, b) for c, a, b in runs]
