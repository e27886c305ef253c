"""Learning a periodic DMP from one periodic segment, eq. (6); the MP is :mod:`lampskit.core.periodic`.

1. Frequency (:func:`estimate_frequency`): remove a linear trend, take the
   Hann-windowed, zero-padded power spectrum summed over dimensions, pick
   the peak (parabolic interpolation on log power) and step down to a
   sub-harmonic ``f/k`` (k = 4, 3, 2) when that holds a real spectral peak
   of at least :data:`SUBHARMONIC_POWER_RATIO` of the peak power: a
   zig-zag's strong second harmonic in one axis must not win. The estimate
   is then refined by the phase fit below; Omega is the fitted phase
   advance over the segment divided by its duration (the mean frequency).
2. Phase (:func:`assign_phase`): a harmonic model fitted by variable
   projection, ``y(t) = c0 + c1 t + sum_{h<=6} a_h cos(h phi(t)) + b_h sin(h phi(t))``
   (coefficients by linear least squares for every trial phase). First a
   linear phase ``phi = Omega t``: a +-4 % grid search around the spectral
   peak, then Levenberg-Marquardt. Then (``follow_drift=True``, default) a
   smooth correction ``phi = Omega t + sum_j p_j B_j(t)``: cubic B-splines
   with one knot interval per cycle and a second-difference penalty
   (weight :data:`PHASE_SPLINE_PENALTY` times the signal variance) that
   ties neighbouring cycles together and keeps the ends steady; stiffened
   tenfold until the phase is monotone (else the linear phase is kept).
   Compared with a Hilbert phase this has no edge errors on a 3-cycle
   segment, uses every dimension and harmonic at once and cannot lock onto
   a harmonic; compared with one global polynomial it does not wag at the
   ends (which would spoil the mean frequency). With +-5 % frequency drift
   over 3-8 cycles the learned cycle matches the demo at its own phase to
   0.7 % of the amplitude (RMS; 1.2 % worst), against 20 % (41 % worst)
   with the constant-frequency phase. Phase zero is where the fundamental
   of the dimension with the largest fundamental amplitude peaks, so the
   template does not depend on where the segmentation cut.
3. Template: GMM-GMR over (phase mod 2*pi, y) (:mod:`.gmr`, K components,
   fed a cubic-spline resampling of 30 K to 2000 samples), evaluated on an
   M-point phase grid. GMR blends local linear models and leaves a ripple
   near harmonic K: about 0.1 % in position but, weighted by k^2, tens of
   per cent in acceleration. A raised-cosine low-pass keeps harmonics
   <= 0.3 K and removes those >= 0.6 K (6 and 12 for K = 20); detail finer
   than the component spacing is beyond the mixture anyway. Raise K to keep
   more harmonics. Then a second cut follows the data: harmonics above the
   last one holding at least 0.5 % of the largest harmonic's amplitude
   (0.25 mm for a 5 cm stroke, below a demonstration's noise and far below
   the eraser's size) are removed (:func:`significant_harmonics`). A
   circle keeps its fundamental, a zig-zag its first few odd harmonics;
   the GMR ripple in between, 0.3-0.9 m/s^2 on a 2 Hz circle, goes.
4. Anchor ``y_m`` = mean of the template; amplitude ``r`` = max over
   dimensions of half the template's peak-to-peak; normalised shape
   ``s = (template - y_m) / r``. With ``d/dt = Omega d/dphi`` eq. (6) reads
   ``f_d / r = s'' + alpha s' + alpha beta s`` (derivatives by FFT on the
   periodic grid). Weights: ridge-regularised least squares of that target
   on the normalised basis of eq. (4); centres evenly spaced on [0, 2*pi),
   one width ``h = -ln 0.8 / (1 - cos(pi / N))`` so neighbouring basis
   functions cross at 80 % of their peak (:func:`default_widths`).
   alpha = 25, beta = alpha / 4: critically damped, the usual DMP choice;
   a perturbation decays as ``exp(-alpha phi / 2)``, i.e. within a quarter
   period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from lampskit.core.periodic import (
    DEFAULT_ALPHA,
    DEFAULT_N_BASIS,
    TWO_PI,
    PeriodicMP,
    default_centres,
    default_widths,
    von_mises_basis,
)
from lampskit.errors import LearningError
from lampskit.learn.gmr import MIN_COMPONENTS, periodic_template
from lampskit.learn.periodic_phase import MIN_OSCILLATION_M, checked_phase_fit, validate_segment

DEFAULT_N_COMPONENTS = 20
DEFAULT_N_TEMPLATE = 512
#: The GMM sees at most this many samples (uniform decimation in time).
MAX_GMM_SAMPLES = 2000
#: The GMM sees at least this many samples per component (upsampled if needed).
GMM_SAMPLES_PER_COMPONENT = 30
#: Template low-pass band edges, in harmonics per GMM component (see :func:`learn_periodic`).
TEMPLATE_PASS_PER_COMPONENT = 0.3
TEMPLATE_STOP_PER_COMPONENT = 0.6
#: Harmonics below this fraction of the largest one, above the last that is not, are removed.
SIGNIFICANT_HARMONIC_FRACTION = 0.005


def forcing_target(
    y: np.ndarray, yd: np.ndarray, ydd: np.ndarray, anchor_m: np.ndarray, omega_rad_s: float, alpha: float, beta: float
) -> np.ndarray:
    """Eq. (6): ``f_d = ydd / Omega^2 - alpha (beta (y_m - y) - yd / Omega)``.

    Parameters
    ----------
    y, yd, ydd : arrays, shape (T, n_dims)
        Position [m], velocity [m/s], acceleration [m/s^2].
    anchor_m : array, shape (n_dims,)
        y_m [m].
    omega_rad_s : float
        Omega [rad/s].
    alpha, beta : float
        Gains of eq. (1).

    Returns
    -------
    f_d : array, shape (T, n_dims) [m]
    """
    return ydd / omega_rad_s**2 - alpha * (beta * (anchor_m - y) - yd / omega_rad_s)


def fit_weights(
    phase_rad: np.ndarray, target: np.ndarray, centres_rad: np.ndarray, widths: np.ndarray, ridge: float = 1e-8
) -> np.ndarray:
    """Least-squares weights of eq. (4): ``min ||Phi W - target||^2 + lambda ||W||^2``.

    ``Phi`` is the normalised basis ``psi_i / sum psi`` and
    ``lambda = ridge * trace(Phi^T Phi) / N``.

    Parameters
    ----------
    phase_rad : array, shape (P,)
        Phases of the target samples [rad].
    target : array, shape (P, n_dims)
        Normalised forcing ``f_d / r``.
    centres_rad, widths : arrays, shape (N,)
    ridge : float
        Relative Tikhonov weight.

    Returns
    -------
    weights : array, shape (N, n_dims)
    """
    psi = von_mises_basis(phase_rad, centres_rad, widths)
    phi = psi / psi.sum(axis=1, keepdims=True)
    gram = phi.T @ phi
    lam = ridge * np.trace(gram) / len(centres_rad)
    return np.linalg.solve(gram + lam * np.eye(len(centres_rad)), phi.T @ target)




def lowpass_periodic(samples: np.ndarray, k_pass: float, k_stop: float) -> np.ndarray:
    """Raised-cosine low-pass of one period sampled on a uniform grid.

    Harmonics k <= k_pass are kept, k >= k_stop removed, a half cosine between.

    Parameters
    ----------
    samples : array, shape (M, n_dims)
        One period, ``samples[j]`` at phase ``2 pi j / M``.
    k_pass, k_stop : float
        Band edges in harmonics (0 < k_pass < k_stop).

    Returns
    -------
    filtered : array, shape (M, n_dims)
    """
    spec = np.fft.rfft(samples, axis=0)
    k = np.arange(spec.shape[0])
    x = np.clip((k - k_pass) / (k_stop - k_pass), 0.0, 1.0)
    gain = 0.5 * (1.0 + np.cos(np.pi * x))
    return np.fft.irfft(spec * gain[:, None], n=len(samples), axis=0)


def significant_harmonics(samples: np.ndarray, fraction: float = SIGNIFICANT_HARMONIC_FRACTION) -> int:
    """Highest harmonic whose amplitude is at least ``fraction`` of the largest one's.

    Parameters
    ----------
    samples : array, shape (M, n_dims)
        One period on a uniform phase grid.
    fraction : float
        In (0, 1).

    Returns
    -------
    int
        Harmonic number k >= 1 (amplitudes taken as the norm over dimensions).
    """
    amp = np.linalg.norm(np.abs(np.fft.rfft(samples, axis=0)[1:]), axis=1)
    return int(np.flatnonzero(amp >= fraction * amp.max())[-1]) + 1


def _periodic_derivatives(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and second phase derivatives of samples on a uniform periodic grid (M, n)."""
    m = len(s)
    spec = np.fft.rfft(s, axis=0)
    k = np.arange(spec.shape[0])[:, None]
    d1 = 1j * k * spec
    if m % 2 == 0:
        d1[-1] = 0.0
    return np.fft.irfft(d1, n=m, axis=0), np.fft.irfft(-(k**2) * spec, n=m, axis=0)


def learn_periodic(
    t_s: np.ndarray,
    y: np.ndarray,
    *,
    n_basis: int = DEFAULT_N_BASIS,
    n_components: int = DEFAULT_N_COMPONENTS,
    alpha: float = DEFAULT_ALPHA,
    beta: float | None = None,
    n_template: int = DEFAULT_N_TEMPLATE,
    follow_drift: bool = True,
    seed: int = 0,
) -> PeriodicMP:
    """Learn a periodic DMP from one periodic segment (see the module docstring).

    Parameters
    ----------
    t_s : array, shape (T,)
        Strictly increasing sample times [s].
    y : array, shape (T, n_dims)
        Positions [m] (e.g. in-plane surface coordinates).
    n_basis : int
        N von-Mises basis functions, >= 3.
    n_components : int
        GMM components for the template.
    alpha, beta : float
        Gains of eq. (1); ``beta`` defaults to ``alpha / 4`` (critical damping).
    n_template : int
        Template grid size M.
    follow_drift : bool
        Phase that follows frequency drift (default) or constant-frequency phase.
    seed : int
        Seed of the GMM initial layout.

    Returns
    -------
    mp : PeriodicMP

    Raises
    ------
    LearningError
        Bad input, too short, not periodic, or bad hyper-parameters.
    """
    beta = alpha / 4.0 if beta is None else beta
    ok_gains = all(math.isfinite(g) and g > 0 for g in (alpha, beta))
    if not (ok_gains and n_basis >= 3 and n_components >= MIN_COMPONENTS and n_template >= 2 * n_basis):
        raise LearningError(
            f"need n_basis >= 3, n_components >= {MIN_COMPONENTS}, finite alpha > 0 and beta > 0, "
            f"n_template >= 2 n_basis; got n_basis={n_basis!r}, n_components={n_components!r}, "
            f"alpha={alpha!r}, beta={beta!r}, n_template={n_template!r}"
        )
    lab = phase_labelled(t_s, y, n_components, follow_drift)
    grid, template, _ = periodic_template(lab.phase_rad, lab.y, n_template, lab.n_components, seed=seed)
    return mp_from_template(grid, template, lab.n_components, lab.omega_rad_s, alpha, beta, n_basis,
                            lab.phase_start_rad, lab.phase_end_rad, lab.n_cycles)


@dataclass(frozen=True, eq=False)
class PhaseLabelled:
    """One periodic segment, phase-labelled for the template (steps 1-2 of the module docstring).

    phase_rad : (K,) phase of each resampled sample [rad] (unwrapped); y : (K, n_dims) positions [m] there (a
    uniform cubic-spline resampling of 30 per component to :data:`MAX_GMM_SAMPLES`); omega_rad_s : mean
    angular frequency [rad/s]; n_components : GMM size for this many samples; phase_start_rad, phase_end_rad :
    phase at the segment's ends mod 2 pi; n_cycles : cycles in the segment.
    """

    phase_rad: np.ndarray
    y: np.ndarray
    omega_rad_s: float
    n_components: int
    phase_start_rad: float
    phase_end_rad: float
    n_cycles: float


def phase_labelled(t_s: np.ndarray, y: np.ndarray, n_components: int = DEFAULT_N_COMPONENTS,
                   follow_drift: bool = True) -> PhaseLabelled:
    """Validate one periodic segment (times (T,) [s], positions (T, n_dims) [m]) and label it with its phase."""
    t, y = validate_segment(t_s, y)
    fit = checked_phase_fit(t, y, follow_drift)
    phase_span = float(fit.phase(t[-1]) - fit.phase(t[0]))
    # The GMM sees a uniform resampling (cubic spline) of at least 30 samples per
    # component: short, fast segments (100 samples) are upsampled, long ones
    # decimated to MAX_GMM_SAMPLES.
    n_gmm = int(np.clip(len(t), GMM_SAMPLES_PER_COMPONENT * n_components, MAX_GMM_SAMPLES))
    t_u = np.linspace(t[0], t[-1], n_gmm)
    y_u = CubicSpline(t, y, axis=0)(t_u)
    n_comp = max(MIN_COMPONENTS, min(int(n_components), n_gmm // 10))
    return PhaseLabelled(fit.phase(t_u), y_u, phase_span / (t[-1] - t[0]), n_comp,
                         float(fit.phase(t[0]) % TWO_PI), float(fit.phase(t[-1]) % TWO_PI), phase_span / TWO_PI)


def mp_from_template(grid: np.ndarray, template: np.ndarray, n_comp: int, omega: float, alpha: float, beta: float,
                     n_basis: int, phase_start_rad: float, phase_end_rad: float, n_cycles: float) -> PeriodicMP:
    """Steps 3-4 after the GMR: low-pass the template (M, n_dims) [m] on ``grid`` (M,) [rad], anchor, amplitude,
    the forcing target of eq. (6) at ``omega`` [rad/s] and its weights."""
    template = lowpass_periodic(template, TEMPLATE_PASS_PER_COMPONENT * n_comp, TEMPLATE_STOP_PER_COMPONENT * n_comp)
    k_last = significant_harmonics(template)
    template = lowpass_periodic(template, k_last + 0.5, k_last + 1.5)
    anchor = template.mean(axis=0)
    amplitude = float(0.5 * (template.max(axis=0) - template.min(axis=0)).max())
    if amplitude < MIN_OSCILLATION_M:
        raise LearningError(
            f"learned template amplitude {amplitude * 1e3:.4f} mm is below {MIN_OSCILLATION_M * 1e3:.2f} mm"
        )
    s = (template - anchor) / amplitude
    ds, dds = _periodic_derivatives(s)
    # Eq. (6) with y = y_m + r s, yd = Omega r s', ydd = Omega^2 r s'', divided by r.
    target = forcing_target(
        template, omega * amplitude * ds, omega**2 * amplitude * dds, anchor, omega, alpha, beta
    ) / amplitude
    centres, widths = default_centres(n_basis), default_widths(n_basis)
    weights = fit_weights(grid, target, centres, widths)
    return PeriodicMP(
        omega_rad_s=omega,
        anchor_m=anchor,
        amplitude_m=amplitude,
        centres_rad=centres,
        widths=widths,
        weights=weights,
        alpha=float(alpha),
        beta=float(beta),
        template_phase_rad=grid,
        template_m=template,
        phase_start_rad=phase_start_rad,
        phase_end_rad=phase_end_rad,
        n_cycles=n_cycles,
    )
