"""Frequency and phase of a periodic segment (step 1 of :mod:`lampskit.learn.periodic_fit`'s learning).

:func:`estimate_frequency` gives Omega [rad/s], :func:`assign_phase` the
phase [rad] of every sample; both rest on one fit of a harmonic model with a
smooth phase correction (see the module docstring of :mod:`lampskit.learn.periodic_fit`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.interpolate import BSpline
from scipy.optimize import least_squares

from lampskit.core.periodic import TWO_PI
from lampskit.errors import LearningError
from lampskit.learn.derivatives import resample_uniform

#: Minimum RMS oscillation after detrending [m]; below this there is nothing to learn.
MIN_OSCILLATION_M = 1e-4
#: A periodic segment must hold at least this many cycles.
MIN_CYCLES = 1.5
#: Minimum fraction of the detrended variance the periodic model must explain.
MIN_PERIODIC_R2 = 0.6
#: Fewer samples than this cannot hold a template (ten per GMM component, four components).
MIN_SEGMENT_SAMPLES = 40
#: Minimum samples per cycle at the estimated frequency.
MIN_SAMPLES_PER_CYCLE = 8
#: A sub-harmonic f/k replaces the spectral peak f when it holds this fraction of the peak power.
SUBHARMONIC_POWER_RATIO = 0.02
#: Knot intervals per cycle of the phase-correction spline.
PHASE_SPLINE_INTERVALS_PER_CYCLE = 1.0
#: Weight of the spline's second-difference penalty, relative to the signal's total variance.
PHASE_SPLINE_PENALTY = 1e-3
#: Harmonics in the phase-fit model.
PHASE_FIT_HARMONICS = 6
#: The phase fit runs on data resampled to this many samples per cycle (at most the input rate).
PHASE_FIT_SAMPLES_PER_CYCLE = 40

class _PhaseFit(NamedTuple):
    """Phase ``phi(t) = omega (t - t_mid) + sum_j p_j B_j(tn) + offset``, tn = (t - t_mid) / half in [-1, 1].

    B_j: cubic B-splines on ``knots`` (none for the constant-frequency phase).
    """

    t_mid_s: float
    half_span_s: float
    omega_rad_s: float
    knots: np.ndarray
    spline_coeffs: np.ndarray
    offset_rad: float
    r2: float

    def phase(self, t_s: np.ndarray) -> np.ndarray:
        tc = np.asarray(t_s, dtype=float) - self.t_mid_s
        out = self.omega_rad_s * tc + self.offset_rad
        if len(self.spline_coeffs):
            out = out + BSpline(self.knots, self.spline_coeffs, 3)(np.clip(tc / self.half_span_s, -1.0, 1.0))
        return out


def validate_segment(t_s, y) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if t.ndim != 1 or y.ndim != 2 or len(t) != len(y):
        raise LearningError(f"periodic segment needs t_s (T,) and y (T, n_dims); got shapes {t.shape} and {y.shape}")
    if len(t) < MIN_SEGMENT_SAMPLES:
        raise LearningError(f"periodic segment too short: {len(t)} samples, need at least {MIN_SEGMENT_SAMPLES}")
    bad = ~(np.isfinite(t) & np.isfinite(y).all(axis=1))
    if bad.any():
        raise LearningError(
            f"periodic segment has NaN or inf at sample {int(np.flatnonzero(bad)[0])} "
            f"({int(bad.sum())} bad sample(s)); every value must be finite"
        )
    if np.any(np.diff(t) <= 0):
        raise LearningError("periodic segment timestamps must increase strictly")
    return t, y


def _detrend(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    a = np.column_stack([np.ones_like(t), t - t.mean()])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return y - a @ coef


def _spectral_frequency_hz(t_u: np.ndarray, y_d: np.ndarray) -> float:
    """Fundamental frequency [Hz] of uniformly sampled, detrended data (T, n)."""
    n_samples = len(t_u)
    dt = t_u[1] - t_u[0]
    duration = n_samples * dt
    n_fft = max(1 << 14, 1 << int(math.ceil(math.log2(16 * n_samples))))
    spec = np.fft.rfft(y_d * np.hanning(n_samples)[:, None], n=n_fft, axis=0)
    power = (spec.real**2 + spec.imag**2).sum(axis=1)
    df = 1.0 / (n_fft * dt)
    lo = int(math.ceil(1.0 / duration / df))
    hi = min(len(power) - 2, int(1.0 / (MIN_SAMPLES_PER_CYCLE * dt) / df))
    if hi <= lo + 2:
        raise LearningError(
            f"periodic segment too short: {duration:.3f} s at {1 / dt:.1f} Hz leaves no frequency band to search"
        )
    idx = lo + int(np.argmax(power[lo:hi]))
    if idx <= lo or power[idx - 1] >= power[idx]:
        raise LearningError(
            f"periodic segment shows no spectral peak: the strongest component is at the lowest resolvable "
            f"frequency ({idx * df:.3f} Hz, one cycle in {duration:.2f} s): too short or not periodic"
        )
    peak = power[idx]
    for k in (4, 3, 2):
        f_c = idx * df / k
        if f_c * duration < MIN_CYCLES:
            continue
        a, b = int(f_c * 0.85 / df), int(math.ceil(f_c * 1.15 / df))
        j = a + int(np.argmax(power[a : b + 1]))
        if a < j < b and power[j] >= SUBHARMONIC_POWER_RATIO * peak:
            idx = j
            break
    return _parabolic_peak(np.log(power[idx - 1 : idx + 2] + 1e-300), idx) * df


def _parabolic_peak(v: np.ndarray, idx: int) -> float:
    """Sub-bin peak position from three samples v[idx-1..idx+1]."""
    den = v[0] - 2.0 * v[1] + v[2]
    return idx + (0.5 * (v[0] - v[2]) / den if den < 0 else 0.0)


def _harmonic_design(phase: np.ndarray, tn: np.ndarray, n_harm: int) -> np.ndarray:
    h = np.arange(1, n_harm + 1)
    arg = phase[:, None] * h
    return np.concatenate([np.ones((len(phase), 1)), tn[:, None], np.cos(arg), np.sin(arg)], axis=1)


def _spline_knots(cycles: float) -> np.ndarray:
    """Clamped cubic knots on [-1, 1] with about one interval per cycle."""
    n_seg = max(1, int(round(cycles * PHASE_SPLINE_INTERVALS_PER_CYCLE)))
    inner = np.linspace(-1.0, 1.0, n_seg + 1)
    return np.concatenate([[-1.0] * 3, inner, [1.0] * 3])


def _fit_phase(t: np.ndarray, y: np.ndarray, follow_drift: bool) -> _PhaseFit:
    """Validated segment -> phase fit (see the module docstring)."""
    t_u, y_u = resample_uniform(t, y)
    y_d = _detrend(t_u, y_u)
    rms = float(np.sqrt((y_d**2).sum(axis=1).mean()))
    if rms < MIN_OSCILLATION_M:
        raise LearningError(
            f"periodic segment does not oscillate: RMS motion after removing a linear trend is "
            f"{rms * 1e3:.4f} mm, need at least {MIN_OSCILLATION_M * 1e3:.2f} mm"
        )
    f0 = _spectral_frequency_hz(t_u, y_d)
    duration = t[-1] - t[0]

    rate = min((len(t_u) - 1) / duration, PHASE_FIT_SAMPLES_PER_CYCLE * f0)
    t_f, y_f = resample_uniform(t_u, y_d, rate)
    t_mid, half = 0.5 * (t[0] + t[-1]), 0.5 * duration
    tc, tn = t_f - t_mid, (t_f - t_mid) / half
    ss_tot = float(((y_f - y_f.mean(axis=0)) ** 2).sum())
    n_harm = PHASE_FIT_HARMONICS

    def solve(phase):
        design = _harmonic_design(phase, tn, n_harm)
        coef, *_ = np.linalg.lstsq(design, y_f, rcond=None)
        return coef, y_f - design @ coef

    # Coarse: linear phase on a +-4 % grid around the spectral peak, refined.
    grid = TWO_PI * f0 * (1.0 + np.linspace(-0.04, 0.04, 33))
    omega0 = grid[int(np.argmin([(solve(w * tc)[1] ** 2).sum() for w in grid]))]
    omega = float(least_squares(lambda v: solve(v[0] * tc)[1].ravel(), [omega0], method="lm").x[0])
    knots, p = np.zeros(0), np.zeros(0)
    if follow_drift:
        # Smooth correction: cubic B-splines, about one interval per cycle, with a
        # second-difference penalty (ties neighbouring cycles, steadies the ends).
        knots = _spline_knots(omega * duration / TWO_PI)
        basis = BSpline.design_matrix(tn.clip(-1.0, 1.0), knots, 3).toarray()
        n_b = basis.shape[1]
        diff2 = np.diff(np.eye(n_b), 2, axis=0)
        for stiffen in (1.0, 10.0, 100.0, None):  # stiffer until the phase is monotone
            if stiffen is None:  # give up: constant-frequency phase
                knots, p = np.zeros(0), np.zeros(0)
                break
            penalty = diff2 * math.sqrt(stiffen * PHASE_SPLINE_PENALTY * ss_tot)
            p = least_squares(
                lambda v, pen=penalty: np.concatenate([solve(omega * tc + basis @ v)[1].ravel(), pen @ v]),
                np.zeros(n_b),
                method="lm",
            ).x
            rate_rad_s = omega + BSpline(knots, p, 3).derivative()(np.linspace(-1.0, 1.0, 401)) / half
            if rate_rad_s.min() > 0.2 * omega:
                break
    phase_f = omega * tc + (BSpline(knots, p, 3)(tn.clip(-1.0, 1.0)) if len(p) else 0.0)
    coef, resid = solve(phase_f)
    r2 = 1.0 - float((resid**2).sum()) / ss_tot
    # Phase zero: the fundamental of the dominant dimension peaks (cos term).
    a, b = coef[2], coef[2 + n_harm]
    dom = int(np.argmax(a**2 + b**2))
    offset = -math.atan2(b[dom], a[dom])
    return _PhaseFit(t_mid, half, omega, knots, p, offset, r2)


def checked_phase_fit(t, y, follow_drift=True) -> _PhaseFit:
    fit = _fit_phase(t, y, follow_drift)
    duration = t[-1] - t[0]
    phase_span = float(fit.phase(t[-1]) - fit.phase(t[0]))
    cycles = phase_span / TWO_PI
    if fit.r2 < MIN_PERIODIC_R2:
        raise LearningError(
            f"periodic segment is not periodic: the best periodic model explains {fit.r2 * 100:.1f} % of "
            f"the detrended motion, need at least {MIN_PERIODIC_R2 * 100:.0f} %"
        )
    if cycles < MIN_CYCLES:
        raise LearningError(
            f"periodic segment too short: {cycles:.2f} cycles at {phase_span / duration / TWO_PI:.3f} Hz "
            f"in {duration:.2f} s, need at least {MIN_CYCLES}"
        )
    rate = (len(t) - 1) / duration
    if rate < MIN_SAMPLES_PER_CYCLE * phase_span / duration / TWO_PI:
        raise LearningError(
            f"periodic segment is sampled too slowly: {rate:.1f} Hz gives fewer than "
            f"{MIN_SAMPLES_PER_CYCLE} samples per cycle"
        )
    return fit


def estimate_frequency(t_s: np.ndarray, y: np.ndarray) -> float:
    """Mean frequency Omega of a periodic segment [rad/s].

    Spectral peak of the detrended signal (power summed over dimensions,
    sub-harmonic check against harmonic lock), refined by the
    phase fit of :func:`assign_phase`; returns the fitted phase advance over
    the segment divided by its duration.

    Parameters
    ----------
    t_s : array, shape (T,)
        Strictly increasing sample times [s] (need not be uniform).
    y : array, shape (T,) or (T, n_dims)
        Positions [m].

    Returns
    -------
    omega_rad_s : float

    Raises
    ------
    LearningError
        Non-finite values, fewer than 1.5 cycles, no oscillation, or no
        periodic structure (explained variance below 60 %).
    """
    t, y = validate_segment(t_s, y)
    fit = checked_phase_fit(t, y)
    return float(fit.phase(t[-1]) - fit.phase(t[0])) / (t[-1] - t[0])


def assign_phase(t_s: np.ndarray, y: np.ndarray, *, follow_drift: bool = True) -> np.ndarray:
    """Phase of every sample of a periodic segment [rad], unwrapped and increasing.

    Parameters
    ----------
    t_s : array, shape (T,)
        Strictly increasing sample times [s].
    y : array, shape (T,) or (T, n_dims)
        Positions [m].
    follow_drift : bool
        True: spline-corrected phase that follows slow frequency drift; False: the
        constant-frequency baseline ``phi = Omega t + phi0``.

    Returns
    -------
    phase_rad : array, shape (T,)
        Zero where the dominant dimension's fundamental peaks (mod 2 pi).
    """
    t, y = validate_segment(t_s, y)
    return checked_phase_fit(t, y, follow_drift).phase(t)
