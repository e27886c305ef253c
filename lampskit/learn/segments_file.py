"""A segmentation a person has corrected: the JSON ``lamps segment --json`` writes, edited by hand, read back
for ``lamps learn --segments FILE``.

The file holds ``segments``: a list, in time order, of objects with ``kind`` (``"periodic"`` or
``"transitional"``), ``cluster`` (optional: a periodic segment without one gets a cluster of its own,
a transitional one -1) and either ``start`` and ``end`` (sample indices, end exclusive) or ``start_s`` and
``end_s`` (times [s] from the demo's first sample, end exclusive: each becomes the first sample at or after
it). To merge two segments delete the boundary between them; to split one at a time, end it there and start
the next there; to relabel, change ``kind``. Everything else in the file (threshold, reachability, cuts) is
ignored. The segments must cover the whole demo without overlaps and gaps: every refusal names the segment
and what is wrong.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lampskit.errors import SegmentationError
from lampskit.learn.demo import Demonstration
from lampskit.learn.segmentation import Segment, Segmentation


def read_segments(path: Path, demo: Demonstration) -> Segmentation:
    """The segmentation in ``path`` (module docstring) checked against ``demo``; method ``"edited"``.

    Raises
    ------
    SegmentationError
        Not JSON, no ``segments`` list, a segment without its bounds, an out-of-range time or sample, an overlap,
        a gap, a bad kind or cluster, no periodic segment.
    """
    where = f"{path}"
    try:
        data = json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise SegmentationError(f"{where}: not JSON ({exc})") from None
    raw = data.get("segments") if isinstance(data, dict) else None
    if not isinstance(raw, list) or not raw:
        raise SegmentationError(f"{where}: needs a non-empty 'segments' list (the JSON 'lamps segment --json' writes)")
    n, t = demo.n_samples, demo.t_s
    bounds = [_bounds(item, i, t, where) for i, item in enumerate(raw)]
    for i, (a, b) in enumerate(bounds):
        if not 0 <= a < b <= n:
            raise SegmentationError(f"{where}: segment {i} [{a}, {b}) is out of range: the demo has samples "
                                    f"0..{n - 1} ({t[-1] - t[0]:.3f} s)")
    if bounds[0][0] != 0:
        raise SegmentationError(f"{where}: gap before segment 0: it starts at sample {bounds[0][0]}, not 0")
    for i in range(1, len(bounds)):
        (_, b0), (a1, _) = bounds[i - 1], bounds[i]
        if a1 < b0:
            raise SegmentationError(f"{where}: overlap: segment {i} starts at sample {a1} ({t[a1] - t[0]:.3f} s), "
                                    f"before segment {i - 1} ends at {b0}")
        if a1 > b0:
            raise SegmentationError(f"{where}: gap between segments {i - 1} and {i}: samples {b0}..{a1 - 1} "
                                    f"({t[b0] - t[0]:.3f}-{t[a1 - 1] - t[0]:.3f} s) belong to none")
    if bounds[-1][1] != n:
        raise SegmentationError(f"{where}: gap after segment {len(bounds) - 1}: it ends at sample {bounds[-1][1]}, "
                                f"the demo at {n}")
    segments = []
    next_cluster = 1 + max([int(item["cluster"]) for item in raw if isinstance(item.get("cluster"), int)] + [-1])
    for i, (item, (a, b)) in enumerate(zip(raw, bounds)):
        kind = item.get("kind")
        cluster = item.get("cluster")
        if cluster is None or (kind == "transitional" and cluster == -1):
            cluster = -1 if kind == "transitional" else next_cluster
            next_cluster += kind != "transitional"
        if kind == "transitional" and cluster != -1:
            cluster = -1  # a relabelled periodic segment keeps its old cluster in the file
        if kind == "periodic" and cluster == -1:
            cluster, next_cluster = next_cluster, next_cluster + 1
        try:
            segments.append(Segment(a, b, kind, int(cluster)))
        except (SegmentationError, TypeError, ValueError) as exc:
            raise SegmentationError(f"{where}: segment {i}: {exc}") from None
    if not any(s.kind == "periodic" for s in segments):
        raise SegmentationError(f"{where}: no periodic segment: nothing to learn")
    labels = np.empty(n, dtype=int)
    for s in segments:
        labels[s.start:s.end] = s.cluster
    return Segmentation(tuple(segments), labels, "edited", None, None, 0.0, np.zeros(0, dtype=int), None)


def _bounds(item: object, i: int, t: np.ndarray, where: str) -> tuple[int, int]:
    if not isinstance(item, dict):
        raise SegmentationError(f"{where}: segment {i} is not an object")
    if "start_s" in item or "end_s" in item:
        try:
            s0, s1 = float(item["start_s"]), float(item["end_s"])
        except (KeyError, TypeError, ValueError):
            raise SegmentationError(f"{where}: segment {i} needs both 'start_s' and 'end_s' as numbers [s]") from None
        span = t[-1] - t[0]
        for name, v in (("start_s", s0), ("end_s", s1)):
            if not (np.isfinite(v) and 0 <= v <= span + 1e-9):
                raise SegmentationError(f"{where}: segment {i} {name}={v!r} is out of range: the demo lasts "
                                        f"0..{span:.3f} s")
        a, b = np.searchsorted(t - t[0], [s0 - 1e-9, s1 - 1e-9])
        return int(a), int(b) if s1 < span - 1e-9 else len(t)
    try:
        a, b = item["start"], item["end"]
    except KeyError:
        raise SegmentationError(f"{where}: segment {i} needs 'start' and 'end' (samples) or 'start_s' and "
                                "'end_s' (seconds)") from None
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (a, b)):
        raise SegmentationError(f"{where}: segment {i} 'start' and 'end' must be sample indices, got {a!r}, {b!r}")
    return a, b
