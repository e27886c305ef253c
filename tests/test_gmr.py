"""GMM-GMR over a periodic phase: template accuracy and the 0 / 2 pi seam."""

from __future__ import annotations

import numpy as np
import pytest

from lampskit.errors import LearningError
from lampskit.learn.gmr import (
    MAX_PHASE_STD_RAD,
    fit_periodic_gmm,
    gmr_mean,
    periodic_template,
    wrap_to_pi,
)

AMP_M = 0.05


def shape_m(phase: np.ndarray) -> np.ndarray:
    """A closed curve with harmonics 1-3, shape (P, 2) [m]."""
    x = AMP_M * (np.cos(phase) + 0.2 * np.cos(3 * phase))
    y = AMP_M * (0.6 * np.sin(phase) + 0.3 * np.sin(2 * phase + 0.4))
    return np.column_stack([x, y]) + np.array([0.3, -0.1])


def noisy_samples(seed: int, n: int = 1200, cycles: float = 6.0, offset_rad: float = 0.0):
    rng = np.random.default_rng(seed)
    phase = offset_rad + np.linspace(0.0, cycles * 2 * np.pi, n)
    return phase, shape_m(phase) + rng.normal(0.0, 5e-4, (n, 2))


@pytest.mark.parametrize("seed", [0, 1])
def test_template_of_noisy_signal_matches_truth(seed):
    phase, y = noisy_samples(seed)
    grid, template, gmm = periodic_template(phase, y, n_points=256, n_components=20, seed=seed)
    assert grid.shape == (256,) and template.shape == (256, 2)
    rmse = np.sqrt(np.mean(np.sum((template - shape_m(grid)) ** 2, axis=1)))
    assert rmse < 0.01 * AMP_M
    assert gmm.converged
    np.testing.assert_allclose(gmm.priors.sum(), 1.0)
    assert np.all((gmm.means[:, 0] >= 0) & (gmm.means[:, 0] < 2 * np.pi))
    assert np.all(np.sqrt(gmm.covariances[:, 0, 0]) <= MAX_PHASE_STD_RAD * (1 + 1e-12))


def test_regression_is_exactly_periodic_and_continuous_across_the_seam():
    phase, y = noisy_samples(3, offset_rad=-0.5)
    gmm = fit_periodic_gmm(phase, y, 16)
    q = np.linspace(-1.0, 1.0, 101)
    np.testing.assert_allclose(gmr_mean(gmm, q), gmr_mean(gmm, q + 2 * np.pi), rtol=0, atol=1e-14)
    # Across 0 / 2 pi: values and slopes agree from both sides.
    eps = 1e-6
    left, right = gmr_mean(gmm, 2 * np.pi - eps), gmr_mean(gmm, eps)
    slope_left = (gmr_mean(gmm, 2 * np.pi - eps) - gmr_mean(gmm, 2 * np.pi - 2 * eps)) / eps
    slope_right = (gmr_mean(gmm, 2 * eps) - gmr_mean(gmm, eps)) / eps
    assert np.abs(left - right).max() < 3 * eps * np.abs(slope_left).max()
    np.testing.assert_allclose(slope_left, slope_right, rtol=1e-3, atol=1e-6)
    # The seam is not special: the same data with phase labels turned by pi
    # (the seam now mid-period) give the same curve near phase 0.
    turned = fit_periodic_gmm(phase + np.pi, y, 16)
    grid = np.linspace(-0.3, 0.3, 61)
    near_seam, mid_period = gmr_mean(gmm, grid), gmr_mean(turned, grid + np.pi)
    assert np.abs(near_seam - mid_period).max() < 0.01 * AMP_M
    assert np.abs(near_seam - shape_m(grid)).max() < 0.03 * AMP_M


def test_no_component_seam_is_visible_anywhere():
    """Each component wraps at mu + pi; its weight there must not make a jump."""
    phase, y = noisy_samples(4)
    gmm = fit_periodic_gmm(phase, y, 8)
    q = np.linspace(0.0, 2 * np.pi, 200_001)
    step = np.abs(np.diff(gmr_mean(gmm, q), axis=0)).max()
    max_slope = np.abs(np.gradient(gmr_mean(gmm, q[::100]), q[::100], axis=0)).max()
    assert step < 1.5 * max_slope * (q[1] - q[0])


def test_scalar_and_array_queries():
    phase, y = noisy_samples(5)
    gmm = fit_periodic_gmm(phase, y, 10)
    assert gmr_mean(gmm, 1.0).shape == (2,)
    assert gmr_mean(gmm, np.array([1.0, 2.0])).shape == (2, 2)
    np.testing.assert_allclose(gmr_mean(gmm, 1.0), gmr_mean(gmm, np.array([1.0]))[0])


def test_fit_is_deterministic_for_a_seed():
    phase, y = noisy_samples(6)
    a, b = fit_periodic_gmm(phase, y, 12, seed=7), fit_periodic_gmm(phase, y, 12, seed=7)
    np.testing.assert_array_equal(a.means, b.means)
    np.testing.assert_array_equal(a.covariances, b.covariances)


def test_one_dimensional_input():
    phase = np.linspace(0, 8 * np.pi, 800)
    gmm = fit_periodic_gmm(phase, np.sin(phase), 12)
    grid = np.linspace(0, 2 * np.pi, 50)
    assert np.abs(gmr_mean(gmm, grid)[:, 0] - np.sin(grid)).max() < 0.02


def test_wrap_to_pi_range():
    x = np.linspace(-20, 20, 1001)
    w = wrap_to_pi(x)
    assert np.all((w >= -np.pi) & (w < np.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(x), atol=1e-12)


@pytest.mark.parametrize(
    "phase, y, k, match",
    [
        (np.zeros(100), np.zeros((99, 2)), 5, "shapes"),
        (np.full(100, np.nan), np.zeros((100, 2)), 5, "NaN"),
        (np.zeros(100), np.zeros((100, 2)), 20, r"n_components=20 is out of range \[4, 10\]"),
        (np.zeros(100), np.zeros((100, 2)), 2, "out of range"),
    ],
)
def test_bad_input_raises_learning_error(phase, y, k, match):
    with pytest.raises(LearningError, match=match):
        fit_periodic_gmm(phase, y, k)
