"""The equations of the third-order transitional MP (eqs. (10)-(19)) and their tabulated solutions.

Pure functions on arrays: the phase, the forcing term's basis, the windowed
crossing target, the gains of eq. (19), the fundamental solutions tabulated
on :data:`N_TABLE` steps of normalised time, and the cubic-Hermite tables
the runners interpolate. The MP that holds them is
:class:`lampskit.core.transitional.TransitionalMP`; the derivation is in
``docs/transitional_mp.md``.
"""

from __future__ import annotations

import math

import numpy as np

#: Steps of the tabulated fundamental solutions over the normalised duration.
N_TABLE = 2048
#: Basis width relative to the spacing of neighbouring centres.
BASIS_OVERLAP = 0.5


def _correction_table(n_steps: int) -> np.ndarray:
    """Rows position, velocity, acceleration, jerk of ``s^3, s^4, s^5`` on ``s = k / n_steps``; shape (K+1, 4, 3)."""
    s = np.linspace(0.0, 1.0, n_steps + 1)
    one = np.ones_like(s)
    return np.stack(
        [np.stack([s**3, s**4, s**5], 1), np.stack([3 * s**2, 4 * s**3, 5 * s**4], 1),
         np.stack([6 * s, 12 * s**2, 20 * s**3], 1), np.stack([6 * one, 24 * s, 60 * s**2], 1)],
        axis=1,
    )


CORRECTION_TABLE = _correction_table(N_TABLE)


def phase(s: np.ndarray | float, lambda_: float) -> np.ndarray | float:
    """Phase ``x = exp(-lambda s)`` at normalised time ``s = t / T`` (solution of eq. 12, tau = T)."""
    return np.exp(-lambda_ * np.asarray(s, dtype=float))


def basis_centres_widths(n_basis: int, lambda_: float, overlap: float = BASIS_OVERLAP) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``c_i`` and widths ``h_i`` of eq. (11), evenly spaced in time.

    Returns
    -------
    centres : array, shape (n_basis,)
        ``exp(-lambda s_i)`` for ``s_i`` evenly spaced on [0, 1].
    widths : array, shape (n_basis,)
        ``h_i = 1 / (2 (overlap * d_i)^2)`` with ``d_i`` the gap to the next centre.
    """
    centres = np.exp(-lambda_ * np.linspace(0.0, 1.0, n_basis))
    gaps = np.abs(np.diff(centres))
    gaps = np.append(gaps, gaps[-1])
    return centres, 1.0 / (2.0 * (overlap * gaps) ** 2)


def forcing_term(x: np.ndarray, weights: np.ndarray, centres: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Eqs. (10)-(11): ``f(x) = sum_i w_i psi_i(x) / sum_i psi_i(x) * x``.

    Parameters
    ----------
    x : array, shape (m,)
        Phase values.
    weights : array, shape (N, n_dims)
    centres, widths : arrays, shape (N,)

    Returns
    -------
    f : array, shape (m, n_dims)
        In normalised jerk units (real jerk contribution ``f / T^3`` [m/s^3]).
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    psi = np.exp(-widths * (x[:, None] - centres) ** 2)
    return (psi @ weights) / np.maximum(psi.sum(axis=1, keepdims=True), 1e-300) * x[:, None]


def crossing_window_s(goal: np.ndarray, duration_s: float, reach_m: float) -> float:
    """Width ``sigma`` [s] of the crossing target's window.

    ``sigma = min(T / 4, reach / |g2|, sqrt(reach / |g3|))`` keeps the target
    within about ``reach`` of ``g1`` (the windowed velocity and acceleration
    parts peak at ``0.61 |g2| sigma`` and ``0.37 |g3| sigma^2``); ``T / 4``
    makes the window negligible (``exp(-8)``) at ``t = 0``. ``reach = inf``
    returns ``inf``: no window, the paper's constant-acceleration target.

    Parameters
    ----------
    goal : array, shape (3, n_dims)
        Entry state ``(g1, g2, g3)`` [m, m/s, m/s^2].
    """
    if math.isinf(reach_m):
        return math.inf
    sigma = duration_s / 4.0
    v, a = float(np.linalg.norm(goal[1])), float(np.linalg.norm(goal[2]))
    if v > 0.0:
        sigma = min(sigma, reach_m / v)
    if a > 0.0:
        sigma = min(sigma, math.sqrt(reach_m / a))
    return sigma


def crossing_target_coefficients(u_s: np.ndarray, sigma_s: float) -> np.ndarray:
    """Coefficients of the crossing target ``r(u) = g1 + w(u) (g2 u + g3 u^2 / 2)``.

    ``w(u) = exp(-u^2 / (2 sigma^2))``; ``u = t - T <= 0``. For ``u > 0``
    (after the transition) the window is dropped: ``r`` is the plain
    constant-acceleration extrapolation of the goal.

    Parameters
    ----------
    u_s : array, shape (m,)
        Time relative to the end of the transition [s].
    sigma_s : float
        Window width [s] (``inf``: no window).

    Returns
    -------
    coef : array, shape (m, 4, 3)
        ``coef[k, d, j]``: the d-th time derivative (position, velocity,
        acceleration, jerk) of ``r`` at ``u_s[k]`` is ``sum_j coef[k, d, j] g_j``
        with ``(g_0, g_1, g_2) = (g1, g2, g3)``.
    """
    u = np.asarray(u_s, dtype=float).reshape(-1)
    a_neg = 0.0 if math.isinf(sigma_s) else -1.0 / sigma_s**2
    a = np.where(u > 0.0, 0.0, a_neg)
    w0 = np.exp(0.5 * a * u * u)
    w1 = a * u * w0
    w2 = (a + a * a * u * u) * w0
    w3 = (3.0 * a * a * u + a**3 * u**3) * w0
    coef = np.zeros((len(u), 4, 3))
    coef[:, 0, 0] = 1.0
    coef[:, 0, 1] = w0 * u
    coef[:, 0, 2] = 0.5 * w0 * u * u
    coef[:, 1, 1] = w1 * u + w0
    coef[:, 1, 2] = 0.5 * w1 * u * u + w0 * u
    coef[:, 2, 1] = w2 * u + 2.0 * w1
    coef[:, 2, 2] = 0.5 * w2 * u * u + 2.0 * w1 * u + w0
    coef[:, 3, 1] = w3 * u + 3.0 * w2
    coef[:, 3, 2] = 0.5 * w3 * u * u + 3.0 * w2 * u + 3.0 * w1
    return coef


def gate_and_gains(s: np.ndarray, p: float, lambda_: float) -> tuple[np.ndarray, np.ndarray]:
    """Gate ``1 - x(s)`` of eq. (13) and the error-feedback gains of eqs. (18)-(19).

    With ``alpha = 3p, beta = p, gamma = p/3``: ``alpha beta gamma = p^3``,
    ``alpha beta = 3 p^2``, ``alpha = 3 p``, i.e. ``P(s) = (s + p/tau)^3``.

    Returns
    -------
    gate : array, shape (m,)
    gains : array, shape (3,)
        ``(p^3, 3 p^2, 3 p)``.
    """
    return np.asarray(1.0 - phase(s, lambda_)), np.array([p**3, 3.0 * p**2, 3.0 * p])


def fundamental_tables(
    p: float, lambda_: float, weights: np.ndarray, centres: np.ndarray, widths: np.ndarray, n_steps: int = N_TABLE
) -> tuple[np.ndarray, np.ndarray]:
    """Tabulate the error dynamics' responses on ``s = k / n_steps``, k = 0..n_steps.

    Integrates ``e' = A(s) e + (0, 0, f(s))`` with classical RK4 (step
    ``1 / n_steps``; with ``p <= 60`` the step is ``p h <= 0.03``, RK4's
    relative error ~1e-9). The per-step affine maps are built for all steps at
    once, then chained.

    Returns
    -------
    phi : array, shape (n_steps + 1, 4, 3)
        Rows: ``e1, e2, e3, de3/ds`` for unit initial error in column j, no forcing.
    forced : array, shape (n_steps + 1, 4, n_dims)
        Rows as ``phi`` for zero initial error and the learned forcing term.
    """
    h = 1.0 / n_steps
    s_half = np.arange(2 * n_steps + 1) * (0.5 * h)
    gate, gains = gate_and_gains(s_half, p, lambda_)
    f_half = forcing_term(np.asarray(phase(s_half, lambda_)), weights, centres, widths)  # (2K+1, n)
    A = np.zeros((2 * n_steps + 1, 3, 3))
    A[:, 0, 1] = A[:, 1, 2] = 1.0
    A[:, 2, :] = -gate[:, None] * gains
    A0, Am, A1 = A[0:-1:2], A[1::2], A[2::2]
    n = weights.shape[1]
    B = np.zeros((2 * n_steps + 1, 3, n))
    B[:, 2, :] = f_half
    b0, bm, b1 = B[0:-1:2], B[1::2], B[2::2]
    eye = np.eye(3)
    K1, c1 = A0, b0
    K2, c2 = Am + 0.5 * h * Am @ K1, 0.5 * h * Am @ c1 + bm
    K3, c3 = Am + 0.5 * h * Am @ K2, 0.5 * h * Am @ c2 + bm
    K4, c4 = A1 + h * A1 @ K3, h * A1 @ c3 + b1
    P = eye + (h / 6.0) * (K1 + 2.0 * K2 + 2.0 * K3 + K4)
    Q = (h / 6.0) * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    state = np.zeros((n_steps + 1, 3, 3 + n))
    state[0, :, :3] = eye
    cur = state[0]
    for k in range(n_steps):
        nxt = P[k] @ cur
        nxt[:, 3:] += Q[k]
        state[k + 1] = nxt
        cur = nxt
    jerk = np.einsum("kj,kjm->km", A[::2, 2, :], state)
    jerk[:, 3:] += f_half[::2]
    full = np.concatenate([state, jerk[:, None, :]], axis=1)
    return full[:, :, :3], full[:, :, 3:]


def hermite_rows(hermite: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Cubic-Hermite interpolation of a table from :func:`hermite_table` at ``s``; shape (m, 3, cols)."""
    k = hermite.shape[0]
    z = np.clip(np.asarray(s, dtype=float), 0.0, 1.0) * k
    i = np.minimum(z.astype(int), k - 1)
    w = hermite_weights(z - i)
    return np.einsum("mk,mkj->mj", w, hermite[i].reshape(len(z), 4, -1)).reshape(len(z), 3, -1)


def hermite_table(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-interval cubic-Hermite data of a table of values and derivatives.

    Parameters
    ----------
    table : array, shape (K + 1, 4, m)
        Rows: ``e1, e2, e3, de3/ds`` (each row the derivative of the one
        before) on ``s = k / K``.

    Returns
    -------
    end : array, shape (3, m)
        Rows 0-2 at ``s = 1``.
    hermite : array, shape (K, 4 * 3 * m)
        For interval k: ``[v_k, h d_k, v_k+1, h d_k+1]`` with ``v`` rows 0-2 and
        ``d`` rows 1-3, so that ``weights @ hermite[k]`` interpolates rows 0-2.
    """
    h = 1.0 / (len(table) - 1)
    hermite = np.stack([table[:-1, :3], h * table[:-1, 1:], table[1:, :3], h * table[1:, 1:]], axis=1)
    hermite = np.ascontiguousarray(hermite.reshape(len(table) - 1, -1))
    end = table[-1, :3].copy()
    hermite.setflags(write=False)
    end.setflags(write=False)
    return end, hermite


def hermite_weights(a: np.ndarray) -> np.ndarray:
    a2, a3 = a * a, a * a * a
    return np.stack([2 * a3 - 3 * a2 + 1, a3 - 2 * a2 + a, -2 * a3 + 3 * a2, a3 - a2], axis=-1)
