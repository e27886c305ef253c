"""Symmetric positive definite systems on the 1 kHz paths: one Cholesky, compiled, allocation-free.

The controller inverts the task-space mass matrix every tick
(:func:`controller.control.kernels.spd_inverse_into`), the simulator solves
the drive's implicit step with the arm's mass matrix every physics step
(:func:`sim.drive.drive_torque_into`); both factor with
:func:`cholesky_lower_in_place` and go on from the factor. Arrays are
``float64``, square ``(n, n)`` or ``(n,)``; nothing is allocated, the caller
owns every buffer. The kernels keep the GIL (numba's ``nogil`` is off), as
every kernel of those loops does.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_jit = nb.njit(cache=True)


@_jit
def cholesky_lower_in_place(L: np.ndarray) -> bool:
    """Factor ``A = L L^T`` in place: on entry the lower triangle of ``L`` (n, n) holds ``A``'s (the upper one is
    not read), on return ``L``'s lower triangle is the factor and its upper triangle zero. Returns False (``L``
    undefined) when ``A`` is not positive definite (a pivot not above 0, NaN included)."""
    n = L.shape[0]
    for j in range(n):
        s = L[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = L[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
        for i in range(j):
            L[i, j] = 0.0
    return True


@_jit
def cholesky_solve_in_place(L: np.ndarray, b: np.ndarray) -> None:
    """``b <- A^-1 b`` for the factor ``L`` (n, n) of :func:`cholesky_lower_in_place` and ``b`` (n,):
    ``L y = b``, then ``L^T x = y``."""
    n = b.shape[0]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * b[k]
        b[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= L[k, i] * b[k]
        b[i] = s / L[i, i]


@_jit
def cholesky_inverse_into(L: np.ndarray, out: np.ndarray) -> None:
    """``out = A^-1`` (n, n), symmetric, from the factor ``L`` of :func:`cholesky_lower_in_place`; ``L`` is
    overwritten (scratch once the inverse is formed)."""
    n = L.shape[0]
    # L^-1 into out's lower triangle, column by column (forward substitution on unit vectors)
    out[:, :] = 0.0
    for j in range(n):
        out[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * out[k, j]
            out[i, j] = s / L[i, i]
    # A^-1 = L^-T L^-1: the lower triangle from sums over the rows below, into L, then mirrored into out
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            for k in range(i, n):
                s += out[k, i] * out[k, j]
            L[i, j] = s
    for i in range(n):
        for j in range(i + 1):
            out[i, j] = L[i, j]
            out[j, i] = L[i, j]
