"""lampskit.spd, the one Cholesky of the controller's and the simulator's 1 kHz paths, against numpy's."""

from __future__ import annotations

import numpy as np
import pytest

from lampskit.spd import cholesky_inverse_into, cholesky_lower_in_place, cholesky_solve_in_place


def _spd(n: int, seed: int, cond: float = 1e3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return (Q * np.geomspace(1.0, 1.0 / cond, n)) @ Q.T


@pytest.mark.parametrize("n, seed", [(1, 0), (6, 1), (7, 2)])
def test_factor_solve_and_inverse_agree_with_numpy_reading_the_lower_triangle_only(n, seed):
    A = _spd(n, seed)
    L = np.tril(A) + np.triu(np.full((n, n), np.nan), 1)  # the upper triangle is never read
    assert cholesky_lower_in_place(L)
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-10, atol=1e-12)
    b = np.random.default_rng(seed).normal(size=n)
    x = b.copy()
    cholesky_solve_in_place(L, x)
    np.testing.assert_allclose(A @ x, b, rtol=1e-9, atol=1e-10)
    out = np.empty((n, n))
    cholesky_inverse_into(L, out)
    np.testing.assert_allclose(out, np.linalg.inv(A), rtol=1e-8, atol=1e-8)
    np.testing.assert_array_equal(out, out.T)


@pytest.mark.parametrize("bad", ["indefinite", "nan", "zero"])
def test_a_matrix_that_is_not_positive_definite_is_refused(bad):
    A = _spd(5, 3)
    if bad == "indefinite":
        A[4, 4] = -1.0
    elif bad == "nan":
        A[2, 2] = np.nan
    else:
        A[:] = 0.0
    assert not cholesky_lower_in_place(np.tril(A))
