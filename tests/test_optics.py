"""Exact OPTICS: equal to sklearn's ``OPTICS(max_eps=inf)`` and to a direct reference loop."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from sklearn.cluster import OPTICS

from lampskit.errors import SegmentationError
from lampskit.learn.optics import OpticsResult, optics, reachability_in_ordering


def _on_grid(x: np.ndarray, cells_per_unit: int) -> np.ndarray:
    """Snap to a binary grid: squared distances are then exact in floating point for sklearn too."""
    return np.round(x * cells_per_unit) / cells_per_unit


def _random(n: int, dims: int, seed: int) -> np.ndarray:
    return _on_grid(np.random.default_rng(seed).normal(size=(n, dims)), 64)


def _duplicated(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = _on_grid(rng.normal(size=(max(2, n // 4), 3)), 64)
    return base[rng.integers(0, len(base), n)]


def _grid(n: int, seed: int) -> np.ndarray:
    """Integer grid points with repeats: many exactly equal distances (ties)."""
    return np.random.default_rng(seed).integers(0, 6, size=(n, 2)).astype(float)


def _trajectory(n: int, seed: int) -> np.ndarray:
    """Loops around two centres joined by a line, like a wiping demo."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    loops = np.c_[0.3 * np.cos(24 * np.pi * t), 0.3 * np.sin(24 * np.pi * t), 0.0 * t]
    centre = np.c_[np.interp(t, [0.0, 0.4, 0.6, 1.0], [0.0, 0.0, 2.0, 2.0]), 0.0 * t, 0.0 * t]
    return _on_grid(centre + loops + rng.normal(scale=0.01, size=(n, 3)), 1024)


CASES = [
    ("random-1d", lambda: _random(120, 1, 0), 5),
    ("random-2d", lambda: _random(200, 2, 1), 2),
    ("random-2d", lambda: _random(200, 2, 2), 10),
    ("random-3d", lambda: _random(300, 3, 3), 4),
    ("random-3d-small", lambda: _random(13, 3, 4), 8),
    ("duplicates", lambda: _duplicated(200, 5), 3),
    ("duplicates", lambda: _duplicated(200, 6), 12),
    ("grid-ties", lambda: _grid(150, 7), 2),
    ("grid-ties", lambda: _grid(150, 8), 6),
    ("grid-ties", lambda: _grid(150, 9), 25),
    ("trajectory", lambda: _trajectory(300, 10), 3),
    ("trajectory", lambda: _trajectory(300, 11), 15),
    ("trajectory", lambda: _trajectory(300, 12), 40),
    ("all-equal", lambda: np.ones((20, 3)), 5),
    ("min_samples=n", lambda: _random(30, 2, 13), 30),
]


@pytest.mark.parametrize(("name", "make", "k"), CASES, ids=[f"{c[0]}-k{c[2]}" for c in CASES])
def test_equals_sklearn(name, make, k):
    x = make()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # sklearn warns about its own xi extraction on flat plots
        ref = OPTICS(min_samples=k, max_eps=np.inf, metric="euclidean").fit(x)
    got = optics(x, k)
    np.testing.assert_array_equal(got.ordering, ref.ordering_)
    np.testing.assert_array_equal(got.reachability, ref.reachability_)
    np.testing.assert_array_equal(got.core_distances, ref.core_distances_)
    np.testing.assert_array_equal(got.predecessor, ref.predecessor_)


def _reference(x: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """sklearn's main loop, written out, with exact (difference-based) distances."""
    n = len(x)
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    core = np.around(np.sort(d, axis=1)[:, k - 1], 15)
    reach = np.full(n, np.inf)
    pred = np.full(n, -1)
    done = np.zeros(n, dtype=bool)
    order = np.zeros(n, dtype=int)
    for i in range(n):
        left = np.flatnonzero(~done)
        p = left[np.argmin(reach[left])]
        done[p] = True
        order[i] = p
        left = np.flatnonzero(~done)
        offer = np.around(np.maximum(d[p, left], core[p]), 15)
        better = offer < reach[left]
        reach[left[better]] = offer[better]
        pred[left[better]] = p
    return order, reach, core, pred


@pytest.mark.parametrize(
    ("make", "k"),
    [
        (lambda: np.random.default_rng(20).normal(size=(400, 3)), 5),
        (lambda: np.random.default_rng(21).uniform(size=(400, 2)) * 1e-3 + 0.7, 9),
        (lambda: np.repeat(np.random.default_rng(22).normal(size=(40, 3)), 5, axis=0), 4),
        # long enough for the lazy parts: batch refills, sentinel groups, tree rebuilds
        (lambda: _trajectory(2500, 23) + np.random.default_rng(23).normal(scale=1e-4, size=(2500, 3)), 4),
        (lambda: _trajectory(2500, 24) + np.random.default_rng(24).normal(scale=1e-4, size=(2500, 3)), 30),
        (lambda: np.vstack([np.random.default_rng(25).normal(size=(800, 3)) * s + 10 * s for s in (1, 0.1, 0.01)]), 7),
    ],
    ids=["normal", "offset-tiny", "repeats", "trajectory-k4", "trajectory-k30", "three-densities"],
)
def test_equals_reference_with_exact_distances(make, k):
    x = make()
    order, reach, core, pred = _reference(x, k)
    got = optics(x, k)
    np.testing.assert_array_equal(got.ordering, order)
    np.testing.assert_array_equal(got.reachability, reach)
    np.testing.assert_array_equal(got.core_distances, core)
    np.testing.assert_array_equal(got.predecessor, pred)


def test_reachability_plot_and_result_are_read_only():
    x = _trajectory(200, 30)
    r = optics(x, 5)
    assert isinstance(r, OpticsResult) and r.min_samples == 5
    plot = reachability_in_ordering(r)
    assert plot.shape == (200,) and np.isinf(plot[0]) and np.all(np.isfinite(plot[1:]))
    np.testing.assert_array_equal(plot, r.reachability_plot)
    assert r.ordering[0] == 0 and r.predecessor[0] == -1
    assert sorted(r.ordering.tolist()) == list(range(200))
    with pytest.raises(ValueError):
        r.reachability[0] = 1.0


def test_progress_is_reported():
    calls = []
    optics(_trajectory(1000, 31), 5, progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (1000, 1000)
    assert len(calls) > 10 and all(t == 1000 for _, t in calls)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


@pytest.mark.parametrize(
    ("points", "k", "match"),
    [
        (np.zeros((5,)), 2, r"shape \(T, n_dims\)"),
        (np.zeros((0, 3)), 2, r"shape \(T, n_dims\)"),
        (np.array([[0.0, 0.0], [np.nan, 1.0], [2.0, 2.0]]), 2, "sample 1 is not"),
        (np.zeros((5, 2)), 1, r"min_samples must be in \[2, 5\]"),
        (np.zeros((5, 2)), 6, r"min_samples must be in \[2, 5\]"),
        (np.zeros((5, 2)), 2.5, "must be an int"),
        (np.zeros((5, 2)), True, "must be an int"),
    ],
)
def test_bad_input_is_rejected(points, k, match):
    with pytest.raises(SegmentationError, match=match):
        optics(points, k)
