"""Exact OPTICS (Ankerst et al. 1999) with ``max_eps = inf`` and the Euclidean metric.

This is the "OPTICS main phase" of the paper's Procedure 1 (section II-A):
an ordering of the samples and their reachability distances, whose plot
(reachability in ordering) shows dense regions as valleys.

The result is that of scikit-learn's
``OPTICS(min_samples=k, max_eps=np.inf, metric="euclidean")`` -- the same
``ordering_``, ``reachability_``, ``core_distances_`` and ``predecessor_`` --
but without sklearn's ``O(n^2)`` per-sample loop: on trajectories the cost
grows close to ``n log n`` (20 000 samples of a 3-D demo take about 0.5-1.5 s
for ``min_samples`` 20-50, 10-15 times less than sklearn; see
``bench/bench_segmentation.py``). The semantics reproduced:

- ``core[p]`` is the distance from ``p`` to its ``min_samples``-th nearest
  sample, ``p`` itself counted; rounded as ``np.around(core, 15)``.
- Processing ``p`` offers every unprocessed ``o`` the reachability
  ``key(p, o) = np.around(max(dist(p, o), core[p]), 15)``; ``o`` keeps its
  smallest offer, and its predecessor is the first processed sample that
  made it (a later, equal offer does not replace it).
- The next sample processed is the unprocessed one with the smallest
  reachability, the lowest index among ties (sample 0 first).

Distances are computed exactly (from coordinate differences, by a KD-tree).
sklearn computes the reachability distances as ``sqrt(|x|^2 - 2 x.y + |y|^2)``,
which differs in the last bits; its rounding to 15 decimals hides most of
that, and on data whose squared distances are exact in floating point
(coordinates on a binary grid) the two results are bit for bit equal.

Algorithm: a Prim-like traversal with lazy neighbour streams. Each processed
sample ``p`` owns a *stream* of its unprocessed neighbours in increasing
``(key(p, o), o)`` order; a heap holds each stream's head as
``(key, o, position of p in the ordering)``. The smallest head is exactly
sklearn's next choice ``(reachability, lowest index)``, and among equal
offers the earliest-processed ``p`` is the predecessor. A stream is served
in *batches*: all neighbours with a key below a bound, read off a k-nearest
neighbour query (first the k-NN of every sample, computed up front; later a
KD-tree over a superset of the unprocessed samples, rebuilt as they are
used up). When a batch runs out, a *sentinel* ``(bound, p)`` in a second
heap stands for the rest of the stream: every neighbour not yet offered has
a key ``>= bound``, so the sentinel is only expanded (by a further query)
when the traversal reaches that level, and sentinels reached together are
expanded in one vectorised query. Samples deep inside a finished dense
region thus cost nothing until the plot climbs to their level. Large k-NN
queries use every core (scipy's ``workers=-1``); the rest is one thread.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from lampskit.errors import SegmentationError

#: sklearn rounds distances to this many decimals (``np.finfo(float64).precision``).
_DECIMALS = np.finfo(np.float64).precision
#: First batch: this many times ``min_samples`` nearest neighbours (at least 16).
_FIRST_FACTOR = 2.0
#: Later batches: queries of this fraction of the first batch (at least 16),
#: doubled for a sample whose query found only processed neighbours.
_REFILL_FACTOR = 0.25
#: Sentinels up to this factor above the one reached are expanded with it.
_GROUP_FACTOR = 1.5
#: The KD-tree of unprocessed samples is rebuilt once more than
#: max(64, remaining / 100) of its samples have been processed.
_STALE_MIN, _STALE_DIV = 64, 100

ProgressCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class OpticsResult:
    """The OPTICS graph of ``T`` samples.

    Attributes
    ----------
    ordering : array of int, shape (T,)
        Sample indices in processing order (sklearn's ``ordering_``).
    reachability : array, shape (T,)
        Reachability distance of each sample, indexed by sample [input
        units, m for positions]; ``inf`` for the first sample processed.
    core_distances : array, shape (T,)
        Distance from each sample to its ``min_samples``-th nearest sample,
        itself included [input units].
    predecessor : array of int, shape (T,)
        Sample that made each sample reachable, -1 for the first.
    min_samples : int
        The ``min_samples`` used.
    """

    ordering: np.ndarray
    reachability: np.ndarray
    core_distances: np.ndarray
    predecessor: np.ndarray
    min_samples: int

    def __post_init__(self) -> None:
        for name in ("ordering", "reachability", "core_distances", "predecessor"):
            getattr(self, name).setflags(write=False)

    @property
    def reachability_plot(self) -> np.ndarray:
        """Reachability in ordering, shape (T,) (see :func:`reachability_in_ordering`)."""
        return reachability_in_ordering(self)


def reachability_in_ordering(result: OpticsResult) -> np.ndarray:
    """The reachability plot ``reachability[ordering]``, shape (T,): valleys are clusters; the first is inf."""
    return result.reachability[result.ordering]


def optics(points: np.ndarray, min_samples: int, *, progress: ProgressCallback | None = None) -> OpticsResult:
    """OPTICS of ``points`` with ``max_eps = inf`` and the Euclidean metric.

    Parameters
    ----------
    points : array, shape (T, n_dims)
        Samples (e.g. tool positions [m]), finite.
    min_samples : int
        Neighbourhood size of the core distance, ``2 <= min_samples <= T``.
    progress : callable, optional
        Called as ``progress(done, T)`` about every 1 % of the samples and
        once with ``done == T`` at the end.

    Returns
    -------
    OpticsResult
        sklearn's ``OPTICS(min_samples, max_eps=inf)`` attributes.
    """
    x = np.asarray(points, dtype=float)
    if x.ndim != 2 or x.shape[0] == 0 or x.shape[1] == 0:
        raise SegmentationError(f"OPTICS needs points of shape (T, n_dims) with T, n_dims >= 1, got {x.shape}")
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        raise SegmentationError(f"OPTICS needs finite points; sample {int(np.flatnonzero(bad)[0])} is not")
    n = len(x)
    if isinstance(min_samples, bool) or not isinstance(min_samples, (int, np.integer)):
        raise SegmentationError(f"min_samples must be an int, got {min_samples!r}")
    if not 2 <= min_samples <= n:
        raise SegmentationError(f"min_samples must be in [2, {n}] for {n} samples, got {min_samples}")
    return _optics_impl(x, int(min_samples), progress)


def _round(values: np.ndarray) -> np.ndarray:
    """``np.around(values, 15)`` (multiply, round half to even, divide), in place on a copy."""
    out = np.multiply(values, 10.0**_DECIMALS)
    np.rint(out, out=out)
    np.divide(out, 10.0**_DECIMALS, out=out)
    return out


def _offers(dists: np.ndarray, ids: np.ndarray, core: np.ndarray,
            complete: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Offers of k-NN query rows, each row sorted by ``(offer, id)``.

    Parameters
    ----------
    dists, ids : arrays, shape (m, k)
        k-NN distances (ascending in each row) and sample ids.
    core : array, shape (m,)
        Core distances of the query samples.
    complete : bool
        The rows hold every sample (no bound beyond them).

    Returns
    -------
    keys, ids : arrays, shape (m, k)
        Offers ``around(max(dist, core), 15)`` and ids, sorted by (offer, id).
    bound : array, shape (m,)
        Every sample missing from a row gets an offer ``>= bound``, so only
        the entries ``< bound`` form a complete batch.
    """
    keys = _round(np.maximum(dists, core[:, None]))
    bound = np.full(len(keys), np.inf) if complete else keys[:, -1].copy()
    # Offers never decrease along a row (max and rounding are monotone), so
    # only runs of equal offers need ordering by id: sort (run start, id).
    m, k = keys.shape
    if k > 1:
        new_run = np.ones((m, k), dtype=bool)
        np.not_equal(keys[:, 1:], keys[:, :-1], out=new_run[:, 1:])
        if not new_run.all():
            run_start = np.maximum.accumulate(np.where(new_run, np.arange(k), 0), axis=1)
            composite = np.sort((run_start.astype(np.int64) << 32) | ids, axis=1)
            ids = composite & 0xFFFFFFFF
            keys = np.take_along_axis(keys, composite >> 32, axis=1)
    return keys, ids, bound


class _Streams:
    """Batches of the samples' neighbour streams (see the module docstring).

    ``processed`` is shared with the traversal: a bytearray (fast scalar
    reads in the Python loop) seen by numpy through ``processed_np``.
    """

    def __init__(self, x: np.ndarray, core: np.ndarray, processed: bytearray, k_refill: int) -> None:
        self.x = x
        self.core = core
        self.processed = processed
        self.processed_np = np.frombuffer(processed, dtype=np.bool_)
        n = len(x)
        self.n = n
        # per sample: current batch (offers and ids sorted by (offer, id)),
        # cursor into it, its bound, and the size of the next query
        self.keys: list[list[float]] = [[]] * n
        self.ids: list[list[int]] = [[]] * n
        self.cursor = [0] * n
        self.bound = [np.inf] * n
        self.k_next = [k_refill] * n
        self.tree: cKDTree | None = None
        self.tree_ids = np.arange(n)
        self.done_at_build = 0

    def refill(self, ps: list[int], n_done: int) -> None:
        """Next batches of samples ``ps`` from the KD-tree of (a superset of) the unprocessed samples."""
        n_left = self.n - n_done
        stale = (self.n - self.done_at_build) - n_left
        if self.tree is None or stale > max(_STALE_MIN, n_left // _STALE_DIV):
            self.tree_ids = np.flatnonzero(~self.processed_np)
            self.tree = cKDTree(self.x[self.tree_ids])
            self.done_at_build = n_done
        by_k: dict[int, list[int]] = {}
        for p in ps:
            by_k.setdefault(self.k_next[p], []).append(p)
        for k_wanted, group in by_k.items():
            self._query(group, k_wanted)

    def _query(self, ps: list[int], k_wanted: int) -> None:
        assert self.tree is not None  # built by refill
        size = len(self.tree_ids)
        k = min(k_wanted, size)
        rows = np.asarray(ps)
        dists, idx = self.tree.query(self.x[rows], k=k, workers=-1 if len(rows) >= 256 else 1)
        ids = self.tree_ids[idx.reshape(len(rows), k)]
        keys, ids, bound = _offers(dists.reshape(len(rows), k), ids, self.core[rows], complete=k >= size)
        # keep the complete part of each row, without processed samples
        keep = (keys < bound[:, None]) & ~self.processed_np[ids]
        ends = np.cumsum(keep.sum(axis=1)).tolist()
        flat_keys, flat_ids = keys[keep].tolist(), ids[keep].tolist()
        start = 0
        for p, end, b in zip(ps, ends, bound.tolist()):
            self.keys[p] = flat_keys[start:end]
            self.ids[p] = flat_ids[start:end]
            self.cursor[p] = 0
            self.bound[p] = b
            if end == start:  # only processed samples that near: look twice as far next time
                self.k_next[p] = 2 * k_wanted
            start = end


def _first_offers(x: np.ndarray, min_samples: int):
    """Core distances (n,) and every sample's first offers from its ``k_first`` nearest neighbours.

    Returns ``(k_first, core, first_keys (n, k_first), first_ids (n, k_first),
    first_bound (list of n floats), first_count (list of n ints))``: a
    sample's offers below its bound, in order, are exact; the rest of its
    stream is refilled on demand (:class:`_Streams`).
    """
    n = len(x)
    k_first = min(n, max(16, int(_FIRST_FACTOR * min_samples)))
    dists, idx = cKDTree(x).query(x, k=k_first, workers=-1)
    dists, idx = dists.reshape(n, k_first), idx.reshape(n, k_first)
    core = _round(dists[:, min_samples - 1])
    first_keys, first_ids, first_bound = _offers(dists, idx, core, complete=k_first >= n)
    first_count = np.sum(first_keys < first_bound[:, None], axis=1).tolist()
    return k_first, core, first_keys, first_ids, first_bound.tolist(), first_count


def _optics_impl(x: np.ndarray, min_samples: int, progress: ProgressCallback | None) -> OpticsResult:
    """The ordering loop. One function on purpose: its locals are bound once for the heap loop's speed."""
    n = len(x)
    k_first, core, first_keys, first_ids, first_bound, first_count = _first_offers(x, min_samples)
    processed = bytearray(n)
    reach = np.full(n, np.inf)
    pred = np.full(n, -1, dtype=int)
    ordering = [0] * n
    streams = _Streams(x, core, processed, max(16, int(_REFILL_FACTOR * k_first)))
    s_keys, s_ids, s_cursor, s_bound = streams.keys, streams.ids, streams.cursor, streams.bound
    processed_np = streams.processed_np
    cand: list[tuple[float, int, int]] = []  # (offer, sample, ordering position of the offering sample)
    sent: list[tuple[float, int]] = []  # (bound, ordering position): the rest of that stream is >= bound
    push, pop = heapq.heappush, heapq.heappop
    every = max(1, n // 100)

    def push_head(p: int, ppos: int) -> None:
        # advance p's cursor past processed samples; push its head, or its sentinel
        ids = s_ids[p]
        i = s_cursor[p]
        n_ids = len(ids)
        while i < n_ids and processed[ids[i]]:
            i += 1
        s_cursor[p] = i
        if i < n_ids:
            push(cand, (s_keys[p][i], ids[i], ppos))
        else:
            push(sent, (s_bound[p], ppos))

    point = 0  # every reachability is inf at first: the lowest index wins
    for pos in range(n):
        processed[point] = 1
        ordering[pos] = point
        if progress is not None and pos % every == 0:
            progress(pos, n)
        if pos == n - 1:
            break
        c = first_count[point]
        row_ids = first_ids[point, :c]
        fresh = ~processed_np[row_ids]
        s_keys[point] = first_keys[point, :c][fresh].tolist()
        s_ids[point] = row_ids[fresh].tolist()
        s_bound[point] = first_bound[point]
        push_head(point, pos)
        while True:
            while cand and processed[cand[0][1]]:
                ppos = pop(cand)[2]
                push_head(ordering[ppos], ppos)
            top = cand[0][0] if cand else np.inf
            if sent and sent[0][0] <= top:
                # A sentinel comes before every offer >= its bound: expand
                # the streams at this level (and a little above) together.
                limit = max(min(top, _GROUP_FACTOR * sent[0][0]), sent[0][0])
                group = []
                while sent and sent[0][0] <= limit:
                    group.append(pop(sent)[1])
                streams.refill([ordering[i] for i in group], pos + 1)
                for i in group:
                    push_head(ordering[i], i)
                continue
            key, o, ppos = pop(cand)
            p = ordering[ppos]
            reach[o] = key
            pred[o] = p
            point = o
            processed[o] = 1
            push_head(p, ppos)
            break
    if progress is not None:
        progress(n, n)
    return OpticsResult(np.asarray(ordering, dtype=int), reach, core, pred, min_samples)
