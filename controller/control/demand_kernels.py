"""The speed override's arithmetic, compiled (numba, as :mod:`.kernels`, whose docstring says why and how): the
joint speeds a reference asks for now and a look ahead along its acceleration (:func:`joint_demand_into`), and
their largest share of the joint speed limits (:func:`largest_share`)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

_jit = nb.njit(cache=True)  # keeps the GIL: see the docstring of controller.control.kernels


@_jit
def _predicted_rate_into(u: np.ndarray, b: np.ndarray, k: int, lookahead_s: float, out: np.ndarray) -> None:
    """``out[k:k+3]``: the rate 3-vector ``u[k:k+3]`` predicted ``lookahead_s`` [s] ahead given its derivative
    ``b[k:k+3]``, see :func:`joint_demand_into`."""
    su, sw, ub = 0.0, 0.0, 0.0
    for i in range(k, k + 3):
        w = u[i] + lookahead_s * b[i]
        su += u[i] * u[i]
        sw += w * w
        ub += u[i] * b[i]
    su, sw = math.sqrt(su), math.sqrt(sw)
    # the magnitude changes with the acceleration along the motion only (through zero: back the other way)
    speed = abs(su + lookahead_s * ub / su) if su > 1e-9 else sw
    f = speed / sw if sw > 1e-12 else 1.0
    for i in range(k, k + 3):
        out[i] = (u[i] + lookahead_s * b[i]) * f if sw > 1e-12 else u[i]


@_jit
def _demand_of(M_inv: np.ndarray, J: np.ndarray, Lam: np.ndarray, v: np.ndarray, w: np.ndarray,
               demand: np.ndarray) -> None:
    """``demand = M^-1 J^T Lam v`` (n,); w (6,) scratch."""
    n = demand.shape[0]
    for r in range(6):
        s = 0.0
        for c in range(6):
            s += Lam[r, c] * v[c]
        w[r] = s
    for i in range(n):
        s = 0.0
        for j in range(n):
            jt = 0.0
            for r in range(6):
                jt += J[r, j] * w[r]
            s += M_inv[i, j] * jt
        demand[i] = s


@_jit
def joint_demand_into(M_inv: np.ndarray, J: np.ndarray, Lam: np.ndarray, twist_ref: np.ndarray,
                      accel_ref: np.ndarray, scale: float, lookahead_s: float, demand: np.ndarray,
                      work: np.ndarray) -> None:
    """Joint speeds (n,) [rad/s] the *unscaled* reference asks for, looking ``lookahead_s`` ahead along its
    acceleration: per joint the larger of ``M^-1 J^T Lam u`` (now) and ``M^-1 J^T Lam v`` (ahead).

    ``u = twist_ref / scale`` is the unscaled twist, ``b = accel_ref / scale^2`` its derivative (the reference
    is stored time-scaled); ``v``'s linear and angular parts each point along ``u + lookahead b`` with the
    magnitude ``|(|u| + lookahead (u . b) / |u|)|``: the speed changes only by the acceleration along the
    motion (through zero it grows back the other way; from rest ``v = lookahead b``). ``|u + lookahead b|``
    itself would count the turning of a curved path as speeding up: on a circle at Omega it over-states the
    speed by ``sqrt(1 + (lookahead Omega)^2)``, 1.4-1.8x at wiping rates, and the override would slow the
    wiping by that much for nothing. work : (4, 7) scratch (n <= 7)."""
    n = demand.shape[0]
    u = work[0]
    v = work[1]
    w = work[2]
    now = work[3]
    inv = 1.0 / scale
    for r in range(6):
        u[r] = twist_ref[r] * inv
        w[r] = accel_ref[r] * inv * inv
    _predicted_rate_into(u, w, 0, lookahead_s, v)
    _predicted_rate_into(u, w, 3, lookahead_s, v)
    _demand_of(M_inv, J, Lam, u, w, now)
    _demand_of(M_inv, J, Lam, v, w, demand)
    for i in range(n):
        if abs(now[i]) > abs(demand[i]):
            demand[i] = now[i]


@_jit
def largest_share(x: np.ndarray, inv_limit: np.ndarray) -> float:
    """``max_i |x_i| * inv_limit_i`` over (n,) arrays."""
    r = 0.0
    for i in range(x.shape[0]):
        r = max(r, abs(x[i]) * inv_limit[i])
    return r
