"""Eq. (4), the periodic DMP's forcing with r = 1, evaluated into preallocated buffers (:class:`ForcingEvaluator`)."""

from __future__ import annotations

import math

import numpy as np

from lampskit.core.periodic import PeriodicMP


class ForcingEvaluator:
    """The forcing F(phi) of one periodic MP with r = 1, one basis evaluation (N exps) per call, no allocation.

    ``[cos phi, sin phi, 1] @ H = h (cos(phi - c) - 1)``, then exp, then ``psi @ [W | 1]`` gives numerator and
    denominator of eq. (4) in one product.

    Attributes
    ----------
    cs : array, shape (3,)
        ``[cos phi, sin phi, 1]`` of the last phase phi [rad].
    h3 : array, shape (3, N)
        ``H``: rows ``h cos c``, ``h sin c``, ``-h`` (widths h, centres c [rad] of the N basis functions).
    w1 : array, shape (N, n_dims + 1)
        ``[W | 1]``: the weights and a column of ones.
    psi : array, shape (N,)
        The basis functions at the last phase.
    num : array, shape (n_dims + 1,)
        ``psi @ [W | 1]``: numerators, then the denominator.
    f_raw : array, shape (n_dims,)
        F before the stroke maps it (used only with a stroke).
    """

    __slots__ = ("cs", "h3", "w1", "psi", "num", "f_raw")

    def __init__(self, mp: PeriodicMP) -> None:
        n = mp.n_dims
        self.cs = np.array([0.0, 0.0, 1.0])
        self.h3 = np.ascontiguousarray(
            np.stack([mp.widths * np.cos(mp.centres_rad), mp.widths * np.sin(mp.centres_rad), -mp.widths])
        )
        self.w1 = np.ascontiguousarray(np.column_stack([mp.weights, np.ones(mp.n_basis)]))
        self.psi = np.empty(mp.n_basis)
        self.num = np.empty(n + 1)
        self.f_raw = np.empty(n)

    def into(self, phase: float, out: np.ndarray, stroke: np.ndarray | None) -> None:
        """F at ``phase`` [rad], mapped by ``stroke`` (n_dims, n_dims) unless None, into ``out`` (n_dims,)."""
        cs, psi, num = self.cs, self.psi, self.num
        cs[0] = math.cos(phase)
        cs[1] = math.sin(phase)
        np.dot(cs, self.h3, out=psi)
        np.exp(psi, out=psi)
        np.dot(psi, self.w1, out=num)
        if stroke is not None:
            np.divide(num[:-1], num[-1], out=self.f_raw)
            np.dot(stroke, self.f_raw, out=out)
        else:
            np.divide(num[:-1], num[-1], out=out)
