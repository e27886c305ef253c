"""The exact one-step map of the periodic DMP, eqs. (1)-(2), and its output map (:class:`StepMaps`).

With ``x = (y1 - y_m, y2)`` per dimension and the phase advancing by ``a = Omega dt``
over a step, ``dx/da = M x + e2 r F`` with ``M = [[0, 1], [-alpha beta, -alpha]]``:
the homogeneous part is propagated exactly (``exp(M a)`` in closed form), the
forcing with a first-order hold (linear in phase across the step).
"""

from __future__ import annotations

import math

import numpy as np


def step_matrix(phase_step_rad: float, alpha: float, beta: float) -> np.ndarray:
    """Exact one-step map of eqs. (1)-(2) for a phase step ``a = Omega dt``.

    With ``x = (y1 - y_m, y2)`` per dimension, ``u0 = r F(phi_k)`` and
    ``du = r (F(phi_k+1) - F(phi_k))`` (forcing linear in phase over the step)::

        x_k+1 = Phi x_k + g0 u0 + g1 du,
        Phi = exp(M a),  g0 = M^-1 (Phi - I) e2,  g1 = (M^-1 g0 - a M^-1 e2) / a,
        M = [[0, 1], [-alpha beta, -alpha]].

    Parameters
    ----------
    phase_step_rad : float
        a = Omega dt > 0 [rad].
    alpha, beta : float

    Returns
    -------
    mat : array, shape (2, 4)
        ``[Phi | g0 | g1]``, to multiply ``(x1, x2, u0, du)`` stacked as rows (4, n).
    """
    return np.array(_step_coefficients(phase_step_rad, alpha, beta)).reshape(2, 4)


def _step_coefficients(a: float, alpha: float, beta: float) -> tuple[float, ...]:
    """Entries of :func:`step_matrix`, row-major, as Python floats (no allocation of arrays)."""
    k, c = alpha * beta, alpha
    mu = -0.5 * c
    disc = 0.25 * c * c - k
    z = disc * a * a
    if abs(z) < 1e-6:
        cc = 1.0 + z / 2.0 + z * z / 24.0
        ss = a * (1.0 + z / 6.0 + z * z / 120.0)
    elif disc > 0:
        q = math.sqrt(disc)
        cc, ss = math.cosh(q * a), math.sinh(q * a) / q
    else:
        q = math.sqrt(-disc)
        cc, ss = math.cos(q * a), math.sin(q * a) / q
    e = math.exp(mu * a)
    p11 = e * (cc - mu * ss)
    p12 = e * ss
    p21 = -k * e * ss
    p22 = e * (cc - mu * ss - c * ss)
    g0_1 = (-c * p12 - (p22 - 1.0)) / k
    g0_2 = p12
    g1_1 = (a - c * g0_1 - g0_2) / (k * a)
    g1_2 = g0_1 / a
    return p11, p12, g0_1, g1_1, p21, p22, g0_2, g1_2


class StepMaps:
    """The two linear maps a :class:`~lampskit.core.periodic_runner.PeriodicRunner` step multiplies by, each
    rebuilt in place only when its parameters change.

    Attributes
    ----------
    alpha, beta : float
        The DMP's gains (dimensionless).
    step : array, shape (2, 4)
        ``[Phi | r g0 | r g1]`` (:func:`step_matrix` with its forcing columns scaled by r) for the phase step
        ``step_key[0]`` = a = Omega dt [rad] and amplitude ``step_key[1]`` = r [m]; it multiplies the state rows
        ``(x1 [m], x2 [m/rad], F, dF)`` (4, n_dims) into the next ``(x1, x2)``.
    out : array, shape (3, 3)
        ``[[1, 0, 0], [0, W, 0], [-ab W^2, -a W^2, r W^2]]`` for ``out_key`` = (W = Omega [rad/s], r [m]): it
        maps ``(x1, x2, F)`` to (position - y_m [m], velocity [m/s], acceleration [m/s^2]).
    """

    __slots__ = ("alpha", "beta", "step", "step_key", "out", "out_key")

    def __init__(self, alpha: float, beta: float) -> None:
        self.alpha, self.beta = alpha, beta
        self.step = np.empty((2, 4))
        self.step_key = (math.nan, math.nan)
        self.out = np.zeros((3, 3))
        self.out[0, 0] = 1.0
        self.out_key = (math.nan, math.nan)

    def rebuild_step(self, a: float, r: float) -> None:
        """:attr:`step` for the phase step ``a`` [rad] and the amplitude ``r`` [m], in place."""
        p11, p12, g01, g11, p21, p22, g02, g12 = _step_coefficients(a, self.alpha, self.beta)
        m = self.step
        m[0, 0], m[0, 1], m[0, 2], m[0, 3] = p11, p12, r * g01, r * g11
        m[1, 0], m[1, 1], m[1, 2], m[1, 3] = p21, p22, r * g02, r * g12
        self.step_key = (a, r)

    def rebuild_out(self, om: float, r: float) -> None:
        """:attr:`out` for Omega = ``om`` [rad/s] and the amplitude ``r`` [m], in place."""
        om2, m = om * om, self.out
        m[1, 1] = om
        m[2, 0], m[2, 1], m[2, 2] = -self.alpha * self.beta * om2, -self.alpha * om2, r * om2
        self.out_key = (om, r)
