"""Gaussian mixture regression over a periodic phase (the GMM-GMR step of Sec. II-C).

The paper smooths each periodic segment with GMM-GMR before learning the
DMP weights: a Gaussian mixture over (phase, position) is fitted with EM,
and Gaussian mixture regression E[y | phi] gives a one-period template.

Phase is an angle, so the mixture must not see a seam at 0 / 2*pi. We run
our own EM with *locally unwrapped* components: component k measures a
sample's phase as ``wrap(phi - mu_k)`` in [-pi, pi), i.e. each Gaussian
lives on the circle centred on its own mean. Everything else is the usual
full-covariance EM. Regression uses the same wrapped offsets, so
``gmr_mean(gmm, phi) == gmr_mean(gmm, phi + 2*pi)`` (to rounding) and the template
is continuous across 0 / 2*pi. A component's seam sits at ``mu_k + pi``,
where its weight is below ``exp(-pi^2 / (2 * MAX_PHASE_STD_RAD^2))``
(about 4e-6) because the phase standard deviation of every component is
capped at :data:`MAX_PHASE_STD_RAD`.

Positions are standardised per dimension inside the fit (so one
``reg_covar`` suits metres and radians) and mapped back to the caller's
units in the returned mixture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lampskit.errors import LearningError

TWO_PI = 2.0 * np.pi
#: Phase standard deviation cap per component [rad]; keeps each component's seam (at mu + pi) invisible.
MAX_PHASE_STD_RAD = np.pi / 5.0
#: Fewer components cannot cover a period with the cap above.
MIN_COMPONENTS = 4


@dataclass(frozen=True, eq=False)
class PeriodicGMM:
    """A Gaussian mixture over (phase, y) with a periodic phase coordinate.

    Attributes
    ----------
    priors : array, shape (K,)
        Mixing weights, summing to one.
    means : array, shape (K, 1 + n_dims)
        Component means: phase [rad] in [0, 2*pi), then y (caller's units).
    covariances : array, shape (K, 1 + n_dims, 1 + n_dims)
        Full covariances in (phase [rad], y) coordinates.
    log_likelihood : float
        Mean log-likelihood per sample at the last EM iteration
        (standardised coordinates).
    n_iter : int
        EM iterations run.
    converged : bool
        Whether the log-likelihood change fell below the tolerance.
    """

    priors: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    log_likelihood: float
    n_iter: int
    converged: bool

    @property
    def n_components(self) -> int:
        return len(self.priors)

    @property
    def n_dims(self) -> int:
        return self.means.shape[1] - 1


def wrap_to_pi(angle_rad: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi).

    Parameters
    ----------
    angle_rad : array, any shape
        Angles [rad].

    Returns
    -------
    wrapped : array, same shape
        ``angle - 2*pi*round(angle / 2*pi)`` in [-pi, pi) [rad].
    """
    return (np.asarray(angle_rad, dtype=float) + np.pi) % TWO_PI - np.pi


def fit_periodic_gmm(
    phase_rad: np.ndarray,
    y: np.ndarray,
    n_components: int = 20,
    *,
    seed: int = 0,
    max_iter: int = 300,
    tol: float = 1e-5,
    reg_covar: float = 1e-6,
) -> PeriodicGMM:
    """Fit a Gaussian mixture over (phase, y) with EM, the phase taken modulo 2*pi.

    Parameters
    ----------
    phase_rad : array, shape (T,)
        Phase of each sample [rad]; any real values (taken modulo 2*pi).
    y : array, shape (T,) or (T, n_dims)
        Positions (any unit; the mixture keeps it).
    n_components : int
        Number of Gaussians K, at least :data:`MIN_COMPONENTS` and at most T / 10.
    seed : int
        Seeds the initial layout: K phase means evenly spaced, rotated by a
        random offset in [0, 2*pi / K).
    max_iter : int
        EM iteration limit.
    tol : float
        Stop when the mean log-likelihood per sample changes less than this.
    reg_covar : float
        Added to the covariance diagonal in standardised coordinates.

    Returns
    -------
    gmm : PeriodicGMM

    Raises
    ------
    LearningError
        Shapes disagree, values are not finite, or K is out of range.
    """
    phase = np.asarray(phase_rad, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if phase.ndim != 1 or y.ndim != 2 or len(phase) != len(y):
        raise LearningError(f"GMM fit needs phase (T,) and y (T, n); got shapes {phase.shape} and {y.shape}")
    if not (np.isfinite(phase).all() and np.isfinite(y).all()):
        raise LearningError("GMM fit got NaN or inf in the phase or positions; every value must be finite")
    n_max = len(phase) // 10
    if not MIN_COMPONENTS <= int(n_components) <= n_max:
        raise LearningError(
            f"n_components={n_components!r} is out of range [{MIN_COMPONENTS}, {n_max}] for {len(phase)} samples"
        )
    if not (reg_covar > 0 and tol > 0 and max_iter >= 1):
        raise LearningError(f"need reg_covar > 0, tol > 0, max_iter >= 1; got {reg_covar}, {tol}, {max_iter}")
    return _fit_impl(phase % TWO_PI, y, int(n_components), seed, int(max_iter), float(tol), float(reg_covar))


def _fit_impl(phase, y, n_comp, seed, max_iter, tol, reg_covar) -> PeriodicGMM:
    n_samples, n_dims = y.shape
    centre = y.mean(axis=0)
    scale = y.std(axis=0)
    scale[scale < 1e-12 * (1.0 + np.abs(centre))] = 1.0
    z = (y - centre) / scale

    rng = np.random.default_rng(seed)
    mu_phi = (np.arange(n_comp) + rng.uniform()) * (TWO_PI / n_comp)
    dphi = wrap_to_pi(phase[None, :] - mu_phi[:, None])  # (K, T)
    resp = _initial_responsibilities(dphi, n_comp)
    ll_old = -np.inf
    converged = False
    eye = np.eye(1 + n_dims)
    for it in range(1, max_iter + 1):  # noqa: B007 (the count of iterations is read after the loop)
        # M-step (from responsibilities): shift each phase mean by the weighted mean offset.
        nk = resp.sum(axis=1) + 10.0 * np.finfo(float).eps  # (K,)
        shift = (resp * dphi).sum(axis=1) / nk
        mu_phi = (mu_phi + shift) % TWO_PI
        mu_y = resp @ z / nk[:, None]  # (K, n)
        d = np.concatenate([(dphi - shift[:, None])[..., None], z[None] - mu_y[:, None]], axis=2)  # (K, T, D)
        cov = np.matmul(np.swapaxes(d * resp[..., None], 1, 2), d) / nk[:, None, None] + reg_covar * eye
        _cap_phase_variance(cov)
        priors = nk / nk.sum()
        # E-step.
        dphi = wrap_to_pi(phase[None, :] - mu_phi[:, None])
        d = np.concatenate([dphi[..., None], z[None] - mu_y[:, None]], axis=2)
        log_p = _log_gauss(d, cov) + np.log(priors)[:, None]  # (K, T)
        log_norm = _logsumexp(log_p, axis=0)
        resp = np.exp(log_p - log_norm)
        ll = float(log_norm.mean())
        if abs(ll - ll_old) < tol:
            converged = True
            break
        ll_old = ll

    # Back to the caller's units: y = centre + scale * z.
    means = np.column_stack([mu_phi, centre + mu_y * scale])
    s = np.concatenate([[1.0], scale])
    covariances = cov * s[None, :, None] * s[None, None, :]
    return PeriodicGMM(priors, means, covariances, ll, it, converged)


def _logsumexp(a: np.ndarray, axis: int, keepdims: bool = False) -> np.ndarray:
    """log(sum(exp(a))) along ``axis``, stable for very negative entries."""
    top = a.max(axis=axis, keepdims=True)
    out = np.log(np.exp(a - top).sum(axis=axis, keepdims=True)) + top
    return out if keepdims else np.squeeze(out, axis=axis)


def _initial_responsibilities(dphi: np.ndarray, n_comp: int) -> np.ndarray:
    """Soft assignment to the nearest phase centre (width one spacing), shape (K, T)."""
    width = TWO_PI / n_comp
    log_r = -0.5 * (dphi / width) ** 2
    return np.exp(log_r - _logsumexp(log_r, axis=0))


def _cap_phase_variance(cov: np.ndarray) -> None:
    """Scale the phase row/column so each phase std is <= MAX_PHASE_STD_RAD (keeps PSD)."""
    var = cov[:, 0, 0]
    factor = np.sqrt(np.minimum(1.0, MAX_PHASE_STD_RAD**2 / var))
    cov[:, 0, :] *= factor[:, None]
    cov[:, :, 0] *= factor[:, None]


def _log_gauss(d: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """log N(d; 0, cov) for d (K, T, D), cov (K, D, D) -> (K, T)."""
    chol = np.linalg.cholesky(cov)
    sol = np.matmul(np.linalg.inv(chol), np.swapaxes(d, 1, 2))  # (K, D, T)
    maha = (sol * sol).sum(axis=1)
    log_det = 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
    return -0.5 * (maha + log_det[:, None] + d.shape[2] * np.log(TWO_PI))


def gmr_mean(gmm: PeriodicGMM, phase_rad: np.ndarray | float) -> np.ndarray:
    """Gaussian mixture regression E[y | phi].

    With h_k(phi) proportional to ``prior_k * N(wrap(phi - mu_k,phi); 0, S_k,phiphi)``,

        E[y | phi] = sum_k h_k(phi) * (mu_k,y + S_k,yphi / S_k,phiphi * wrap(phi - mu_k,phi)).

    Parameters
    ----------
    gmm : PeriodicGMM
    phase_rad : float or array, shape (P,)
        Query phases [rad], any real values.

    Returns
    -------
    mean : array, shape (n_dims,) for a scalar phase, else (P, n_dims)
        Conditional mean, in the units of the fitted y.
    """
    scalar = np.ndim(phase_rad) == 0
    q = np.atleast_1d(np.asarray(phase_rad, dtype=float))
    mean = _gmr_impl(gmm, q)
    return mean[0] if scalar else mean


def _gmr_impl(gmm: PeriodicGMM, q: np.ndarray) -> np.ndarray:
    mu_phi = gmm.means[:, 0]
    var = gmm.covariances[:, 0, 0]
    slope = gmm.covariances[:, 1:, 0] / var[:, None]  # (K, n)
    dphi = wrap_to_pi(q[:, None] - mu_phi[None, :])  # (P, K)
    log_w = np.log(gmm.priors)[None, :] - 0.5 * (dphi**2 / var[None, :] + np.log(TWO_PI * var)[None, :])
    h = np.exp(log_w - _logsumexp(log_w, axis=1, keepdims=True))  # (P, K)
    cond = gmm.means[None, :, 1:] + dphi[..., None] * slope[None]  # (P, K, n)
    return np.einsum("pk,pkn->pn", h, cond)


def periodic_template(
    phase_rad: np.ndarray,
    y: np.ndarray,
    n_points: int = 512,
    n_components: int = 20,
    *,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, PeriodicGMM]:
    """One-period template of a phase-labelled periodic signal by GMM-GMR.

    Parameters
    ----------
    phase_rad : array, shape (T,)
        Phase of each sample [rad] (any real values; folded modulo 2*pi).
    y : array, shape (T, n_dims)
        Positions.
    n_points : int
        Template grid size M (phases ``2*pi*j/M``, j = 0..M-1).
    n_components : int
        Mixture size K.
    seed : int
        See :func:`fit_periodic_gmm`.

    Returns
    -------
    grid_rad : array, shape (M,)
        Evenly spaced phases on [0, 2*pi) [rad].
    template : array, shape (M, n_dims)
        E[y | phi] on the grid.
    gmm : PeriodicGMM
        The fitted mixture.
    """
    if int(n_points) < 8:
        raise LearningError(f"template needs at least 8 grid points, got n_points={n_points!r}")
    gmm = fit_periodic_gmm(phase_rad, y, n_components, seed=seed)
    grid = TWO_PI * np.arange(int(n_points)) / int(n_points)
    return grid, _gmr_impl(gmm, grid), gmm
