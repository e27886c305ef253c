"""The stains' visiting order (point 1 of :mod:`lampskit.core.planner`): the shortest open path from the tool
through every stain, exact for up to :data:`EXACT_ORDER_MAX` stains, nearest neighbour and 2-opt above."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from lampskit.core.planner_types import Stain

#: Up to this many stains the visiting order is found by exhaustive search.
EXACT_ORDER_MAX = 7


def order_stains(stains: Sequence[Stain], start_m: np.ndarray) -> list[Stain]:
    """Visiting order that shortens the path start -> s1 -> s2 -> ... (open path).

    Up to :data:`EXACT_ORDER_MAX` stains the shortest order of all (every permutation's length at once from the
    distance matrix: 5,040 orders of 7 stains in about 1 ms); more: nearest neighbour, then 2-opt (the segment
    reversal that shortens the path most, from a matrix of every reversal's gain) until none does.
    """
    pts = np.array([s.centre_m for s in stains], dtype=float).reshape(-1, 2)
    n = len(pts)
    if n <= 2:
        d = np.linalg.norm(pts - start_m, axis=1)
        return [stains[i] for i in np.argsort(d, kind="stable")]
    nodes = np.vstack([start_m, pts])  # node 0 is the start
    D = np.linalg.norm(nodes[:, None, :] - nodes[None, :, :], axis=2)
    if n <= EXACT_ORDER_MAX:
        perms = _permutations(n) + 1
        lengths = D[0, perms[:, 0]] + D[perms[:, :-1], perms[:, 1:]].sum(axis=1)
        return [stains[i - 1] for i in perms[int(np.argmin(lengths))]]
    # nearest neighbour from the start (ties to the lower index)
    order, here = [], 0
    left = np.ones(n + 1, dtype=bool)
    left[0] = False
    for _ in range(n):
        nxt = int(np.argmin(np.where(left, D[here], np.inf)))
        order.append(nxt)
        left[nxt] = False
        here = nxt
    return [stains[i - 1] for i in _two_opt(np.array(order), D)]


def _two_opt(order: np.ndarray, D: np.ndarray) -> np.ndarray:
    """2-opt on the open path 0 -> order[0] -> ... (node indices into ``D`` (n+1, n+1)): reverse order[i..j]
    while a reversal shortens it, the best one each time."""
    n = len(order)
    i_idx, j_idx = np.triu_indices(n, 1)
    while True:
        a = np.concatenate([[0], order])  # a[k + 1] is order[k]
        before, first, last = a[i_idx], a[i_idx + 1], a[j_idx + 1]
        gain = D[before, first] - D[before, last]  # edge into the reversed run
        inner = j_idx + 2 < n + 1
        after = a[np.minimum(j_idx + 2, n)]
        gain += np.where(inner, D[last, after] - D[first, after], 0.0)  # edge out of it (none at the path's end)
        k = int(np.argmax(gain))
        if gain[k] <= 1e-12:
            return order
        i, j = i_idx[k], j_idx[k]
        order = np.concatenate([order[:i], order[i:j + 1][::-1], order[j + 1:]])


_PERMS: dict[int, np.ndarray] = {}


def _permutations(n: int) -> np.ndarray:
    """Every permutation of range(n) (n!, n), lexicographic (itertools' order), cached."""
    if n not in _PERMS:
        _PERMS[n] = np.array(list(itertools.permutations(range(n))), dtype=np.intp)
    return _PERMS[n]
