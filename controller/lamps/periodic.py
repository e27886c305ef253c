"""Periodic dynamic movement primitives, paper eqs. (1)-(6).

The periodic DMP (Sec. II-C), with ``y1`` the position and ``y2`` the
velocity divided by the frequency::

    dy2/dt = Omega * (alpha * (beta * (y_m - y1) - y2) + f(phi))        (1)
    dy1/dt = Omega * y2                                                 (2)
    dphi/dt = Omega            (eq. (3) with tau = 1 / Omega, phi in rad)
    f(phi) = r * sum_i w_i psi_i(phi) / sum_i psi_i(phi)                (4)
    psi_i(phi) = exp(h_i * (cos(phi - c_i) - 1))                        (5)
    f_d = ydd / Omega^2 - alpha * (beta * (y_m - y) - yd / Omega)       (6)

Learning (:func:`learn_periodic`)
---------------------------------
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

Closed form (:func:`periodic_state`)
------------------------------------
With ``y1 = y_m + r s(phi)`` eqs. (1)-(2) become the linear ODE
``s'' + alpha s' + alpha beta s = F(phi)``, ``F = sum w psi / sum psi``. Its
periodic steady state (the limit cycle) is exact in Fourier space:
``S_k = F_k / (-k^2 + i alpha k + alpha beta)``. We sample F on a grid fine
enough for the basis bandwidth, FFT, divide, and keep the harmonics above
1e-13 of the largest. Position, velocity and acceleration at any phase are
``y_m + r s``, ``Omega r s'``, ``Omega^2 r s''``.

Execution (:class:`PeriodicRunner`)
-----------------------------------
Exponential integrator: over one step of length dt the phase advances by
``a = Omega dt`` and ``x = (y1 - y_m, y2)`` obeys ``dx/da = M x + e2 r F``
with ``M = [[0, 1], [-alpha beta, -alpha]]``. The homogeneous part is
propagated exactly (``exp(M a)`` in closed form), the forcing with a
first-order hold (linear in phase across the step). This is unconditionally
stable for every Omega and dt (the DMP poles sit at ``-alpha Omega / 2``,
e.g. -236 rad/s at 3 Hz), second-order accurate in the forcing, and needs
one basis evaluation (N exps) per step, unlike RK4 (three). Changes of
``y_m``, ``r`` and ``Omega`` go through critically damped second-order
filters (time constant :data:`DEFAULT_RAMP_TIME_CONSTANT_S`), so the
effective parameters are C1 and the output position, velocity and
acceleration stay continuous.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from scipy.interpolate import BSpline, CubicSpline
from scipy.optimize import least_squares

from .derivatives import resample_uniform
from .errors import LearningError, PlanningError, SkillFileError
from .gmr import MIN_COMPONENTS, periodic_template

TWO_PI = 2.0 * np.pi

DEFAULT_ALPHA = 25.0
DEFAULT_N_BASIS = 50
DEFAULT_N_COMPONENTS = 20
DEFAULT_N_TEMPLATE = 512
#: A periodic segment must hold at least this many cycles.
MIN_CYCLES = 1.5
#: Minimum fraction of the detrended variance the periodic model must explain.
MIN_PERIODIC_R2 = 0.6
#: Minimum RMS oscillation after detrending [m]; below this there is nothing to learn.
MIN_OSCILLATION_M = 1e-4
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
#: The GMM sees at most this many samples (uniform decimation in time).
MAX_GMM_SAMPLES = 2000
#: The GMM sees at least this many samples per component (upsampled if needed).
GMM_SAMPLES_PER_COMPONENT = 30
#: Height at which neighbouring basis functions cross (sets the widths h).
BASIS_CROSSING = 0.8
#: Template low-pass band edges, in harmonics per GMM component (see :func:`learn_periodic`).
TEMPLATE_PASS_PER_COMPONENT = 0.3
TEMPLATE_STOP_PER_COMPONENT = 0.6
#: Harmonics below this fraction of the largest one, above the last that is not, are removed.
SIGNIFICANT_HARMONIC_FRACTION = 0.005
#: Default time constant tau of the critically damped parameter filters [s]: a step
#: in a target is 90 % done after 3.9 tau (0.78 s), with no overshoot.
DEFAULT_RAMP_TIME_CONSTANT_S = 0.2
#: update() rejects steps longer than this [s].
MAX_DT_S = 0.1
SKILL_KIND = "periodic_dmp"
SKILL_VERSION = 1


# --------------------------------------------------------------------------- basis, eqs. (4)-(6)


def default_centres(n_basis: int) -> np.ndarray:
    """Basis centres ``c_i = 2 pi i / N``, shape (N,) [rad]."""
    return TWO_PI * np.arange(n_basis) / n_basis


def default_widths(n_basis: int) -> np.ndarray:
    """Basis widths ``h = -ln(0.8) / (1 - cos(pi / N))``, shape (N,).

    Neighbouring von-Mises functions (eq. (5)) then cross at 80 % of their
    peak, midway between their centres (h about 0.045 N^2; 113 for N = 50).
    Narrower bases (crossing at half height) give a staircase-like forcing
    with more high harmonics; wider ones make the regression ill-conditioned.
    """
    return np.full(n_basis, -math.log(BASIS_CROSSING) / (1.0 - math.cos(math.pi / n_basis)))


def von_mises_basis(phase_rad: np.ndarray | float, centres_rad: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Eq. (5): ``psi_i(phi) = exp(h_i (cos(phi - c_i) - 1))``.

    Parameters
    ----------
    phase_rad : float or array, shape (P,)
        Phases [rad].
    centres_rad : array, shape (N,)
        Centres c_i [rad].
    widths : array, shape (N,)
        Concentrations h_i > 0 (dimensionless).

    Returns
    -------
    psi : array, shape (N,) for a scalar phase, else (P, N)
    """
    phase = np.asarray(phase_rad, dtype=float)
    return np.exp(widths * (np.cos(phase[..., None] - centres_rad) - 1.0))


def forcing(
    phase_rad: np.ndarray | float,
    centres_rad: np.ndarray,
    widths: np.ndarray,
    weights: np.ndarray,
    amplitude_m: float = 1.0,
) -> np.ndarray:
    """Eq. (4): ``f(phi) = r sum_i w_i psi_i / sum_i psi_i``.

    Parameters
    ----------
    phase_rad : float or array, shape (P,)
        Phases [rad].
    centres_rad, widths : arrays, shape (N,)
        Basis of eq. (5).
    weights : array, shape (N, n_dims)
        w_i per dimension (forcing per unit amplitude).
    amplitude_m : float
        r [m]; 1 gives the normalised forcing F.

    Returns
    -------
    f : array, shape (n_dims,) for a scalar phase, else (P, n_dims) [m]
    """
    psi = von_mises_basis(phase_rad, centres_rad, widths)
    return amplitude_m * (psi @ weights) / psi.sum(axis=-1, keepdims=True)


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


# --------------------------------------------------------------------------- closed form


def limit_cycle_coefficients(
    centres_rad: np.ndarray, widths: np.ndarray, weights: np.ndarray, alpha: float, beta: float
) -> np.ndarray:
    """Fourier coefficients of the normalised limit cycle s(phi) of eqs. (1)-(2).

    ``s(phi) = Re(sum_k c_k exp(i k phi))``, k = 0..K, solving
    ``s'' + alpha s' + alpha beta s = F(phi)`` exactly (F from eq. (4) with r = 1).

    Parameters
    ----------
    centres_rad, widths : arrays, shape (N,)
    weights : array, shape (N, n_dims)
    alpha, beta : float

    Returns
    -------
    coeffs : complex array, shape (K + 1, n_dims)
        One-sided coefficients (k >= 1 already doubled).
    """
    # von Mises of concentration h has Fourier coefficients ~ exp(-k^2 / (2 h)):
    # below 1e-16 for k > sqrt(2 h 37). Sample four times finer than that.
    k_needed = math.sqrt(2.0 * float(np.max(widths)) * 37.0) + 8.0
    n_grid = max(1024, 1 << int(math.ceil(math.log2(4.0 * k_needed))))
    grid = TWO_PI * np.arange(n_grid) / n_grid
    f_k = np.fft.rfft(forcing(grid, centres_rad, widths, weights), axis=0) / n_grid
    k = np.arange(f_k.shape[0])
    coeffs = f_k / (-(k**2) + 1j * alpha * k + alpha * beta)[:, None]
    coeffs[1:] *= 2.0
    coeffs[-1] = 0.0  # the Nyquist term is not a one-sided harmonic; negligible anyway
    size = np.abs(coeffs).max(axis=1) * np.maximum(1, k) ** 2
    keep = np.flatnonzero(size > 1e-13 * size.max())
    return coeffs[: (keep[-1] + 1 if keep.size else 1)]


def periodic_state(
    mp: "PeriodicMP",
    phase_rad: np.ndarray | float,
    anchor_m: np.ndarray | None = None,
    amplitude_m: float | None = None,
    omega_rad_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration on the DMP's limit cycle at a phase.

    Parameters
    ----------
    mp : PeriodicMP
    phase_rad : float or array, shape (P,)
        Phases [rad], any real values.
    anchor_m : array, shape (n_dims,), optional
        y_m [m]; default ``mp.anchor_m``.
    amplitude_m : float, optional
        r [m]; default ``mp.amplitude_m``.
    omega_rad_s : float, optional
        Omega [rad/s]; default ``mp.omega_rad_s``.

    Returns
    -------
    pos, vel, acc : arrays, shape (n_dims,) for a scalar phase, else (P, n_dims)
        In [m], [m/s], [m/s^2].

    Raises
    ------
    PlanningError
        Non-finite phase, wrong anchor shape, non-positive amplitude or frequency.
    """
    anchor, amp, omega = _check_execution_params(mp, anchor_m, amplitude_m, omega_rad_s)
    phase = np.asarray(phase_rad, dtype=float)
    if phase.ndim > 1 or not np.isfinite(phase).all():
        raise PlanningError(f"phase_rad must be a finite scalar or 1-D array, got shape {phase.shape}")
    return _periodic_state_impl(mp._stacked, phase, anchor, amp, omega)


def _periodic_state_impl(stacked, phase, anchor, amp, omega):
    """Unchecked closed form; ``stacked`` = [c, i k c, -k^2 c] as (K+1, 3n)."""
    n = stacked.shape[1] // 3
    k = np.arange(stacked.shape[0])
    e = np.exp(1j * np.multiply.outer(phase, k))
    out = (e @ stacked).real
    s, ds, dds = out[..., :n], out[..., n : 2 * n], out[..., 2 * n :]
    return anchor + amp * s, (omega * amp) * ds, (omega * omega * amp) * dds


def _check_execution_params(mp, anchor_m, amplitude_m, omega_rad_s):
    n = mp.n_dims
    anchor = mp.anchor_m if anchor_m is None else np.asarray(anchor_m, dtype=float)
    if anchor.shape != (n,) or not np.isfinite(anchor).all():
        raise PlanningError(f"anchor_m must be a finite array of shape ({n},), got {anchor_m!r}")
    amp = mp.amplitude_m if amplitude_m is None else float(amplitude_m)
    if not (math.isfinite(amp) and amp > 0):
        raise PlanningError(f"amplitude_m must be finite and > 0 m, got {amplitude_m!r}")
    omega = mp.omega_rad_s if omega_rad_s is None else float(omega_rad_s)
    if not (math.isfinite(omega) and omega > 0):
        raise PlanningError(f"omega_rad_s must be finite and > 0 rad/s, got {omega_rad_s!r}")
    return anchor, amp, omega


# --------------------------------------------------------------------------- the learned primitive


def _as_array(value, name: str, ndim: int) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SkillFileError(f"periodic MP field {name!r} is not numeric: {exc}") from None
    if arr.ndim != ndim:
        raise SkillFileError(f"periodic MP field {name!r} must be {ndim}-D, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise SkillFileError(f"periodic MP field {name!r} holds NaN or inf; every value must be finite")
    return arr


def _as_float(value, name: str, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise SkillFileError(f"periodic MP field {name!r} must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x) or (positive and x <= 0):
        raise SkillFileError(f"periodic MP field {name!r} must be finite{' and > 0' if positive else ''}, got {x!r}")
    return x


_SCALARS_POSITIVE = ("omega_rad_s", "amplitude_m", "alpha", "beta")
_SCALARS_ANY = ("phase_start_rad", "phase_end_rad", "n_cycles")
_ARRAYS = (
    ("anchor_m", 1),
    ("centres_rad", 1),
    ("widths", 1),
    ("weights", 2),
    ("template_phase_rad", 1),
    ("template_m", 2),
)


@dataclass(frozen=True, eq=False)
class PeriodicMP:
    """A learned periodic DMP, eqs. (1)-(6).

    Attributes
    ----------
    omega_rad_s : float
        Omega, the mean demonstrated frequency [rad/s] (> 0).
    anchor_m : array, shape (n_dims,)
        y_m, the attractor point [m].
    amplitude_m : float
        r, the amplitude [m]: max over dimensions of half the template's peak-to-peak (> 0).
    centres_rad : array, shape (N,)
        von-Mises centres c_i [rad].
    widths : array, shape (N,)
        von-Mises concentrations h_i (> 0).
    weights : array, shape (N, n_dims)
        w_i of eq. (4), forcing per unit amplitude.
    alpha, beta : float
        Gains of eq. (1) (> 0).
    template_phase_rad : array, shape (M,)
        Phase grid of the GMR template [rad], in [0, 2 pi).
    template_m : array, shape (M, n_dims)
        GMR template (for plots and checks) [m].
    phase_start_rad, phase_end_rad : float
        Phase of the segment's first and last sample [rad], in [0, 2 pi).
    n_cycles : float
        Cycles demonstrated in the segment.
    """

    omega_rad_s: float
    anchor_m: np.ndarray
    amplitude_m: float
    centres_rad: np.ndarray
    widths: np.ndarray
    weights: np.ndarray
    alpha: float
    beta: float
    template_phase_rad: np.ndarray
    template_m: np.ndarray
    phase_start_rad: float = 0.0
    phase_end_rad: float = 0.0
    n_cycles: float = 0.0
    _stacked: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name in _SCALARS_POSITIVE:
            object.__setattr__(self, name, _as_float(getattr(self, name), name, positive=True))
        for name in _SCALARS_ANY:
            object.__setattr__(self, name, _as_float(getattr(self, name), name, positive=False))
        arrays = {name: _as_array(getattr(self, name), name, ndim) for name, ndim in _ARRAYS}
        n = arrays["anchor_m"].shape[0]
        n_basis = arrays["centres_rad"].shape[0]
        n_tmpl = arrays["template_phase_rad"].shape[0]
        expected = {
            "anchor_m": (n,),
            "widths": (n_basis,),
            "weights": (n_basis, n),
            "template_m": (n_tmpl, n),
        }
        if n < 1 or n_basis < 3:
            raise SkillFileError(f"periodic MP needs n_dims >= 1 and at least 3 basis functions, got {n} and {n_basis}")
        for name, shape in expected.items():
            if arrays[name].shape != shape:
                raise SkillFileError(f"periodic MP field {name!r} must have shape {shape}, got {arrays[name].shape}")
        if np.any(arrays["widths"] <= 0):
            raise SkillFileError("periodic MP field 'widths' must be > 0 everywhere")
        for name, value in arrays.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        coeffs = limit_cycle_coefficients(self.centres_rad, self.widths, self.weights, self.alpha, self.beta)
        k = np.arange(coeffs.shape[0])[:, None]
        stacked = np.ascontiguousarray(np.concatenate([coeffs, 1j * k * coeffs, -(k**2) * coeffs], axis=1))
        stacked.setflags(write=False)
        object.__setattr__(self, "_stacked", stacked)

    @property
    def n_dims(self) -> int:
        return self.anchor_m.shape[0]

    @property
    def n_basis(self) -> int:
        return self.centres_rad.shape[0]

    @property
    def period_s(self) -> float:
        return TWO_PI / self.omega_rad_s

    def to_dict(self) -> dict:
        """Plain-JSON form: every attribute above under its own name, plus a tag.

        ``{"kind": "periodic_dmp", "version": 1, "omega_rad_s": float,
        "anchor_m": [n], "amplitude_m": float, "centres_rad": [N],
        "widths": [N], "weights": [N][n], "alpha": float, "beta": float,
        "template_phase_rad": [M], "template_m": [M][n],
        "phase_start_rad": float, "phase_end_rad": float, "n_cycles": float}``.
        :meth:`from_dict` rejects another kind or version, missing or unknown
        keys, wrong shapes, non-finite values and non-positive omega,
        amplitude, gains or widths, with a SkillFileError naming the field.
        """
        out: dict = {"kind": SKILL_KIND, "version": SKILL_VERSION}
        for name in _SCALARS_POSITIVE + _SCALARS_ANY:
            out[name] = float(getattr(self, name))
        for name, _ in _ARRAYS:
            out[name] = np.asarray(getattr(self, name), dtype=float).tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "PeriodicMP":
        """Inverse of :meth:`to_dict`; raises SkillFileError naming the bad field."""
        if not isinstance(data, dict):
            raise SkillFileError(f"periodic MP must be a JSON object, got {type(data).__name__}")
        if data.get("kind") != SKILL_KIND:
            raise SkillFileError(f"periodic MP field 'kind' must be {SKILL_KIND!r}, got {data.get('kind')!r}")
        if data.get("version") != SKILL_VERSION:
            raise SkillFileError(f"periodic MP field 'version' must be {SKILL_VERSION}, got {data.get('version')!r}")
        names = set(_SCALARS_POSITIVE + _SCALARS_ANY) | {name for name, _ in _ARRAYS}
        missing = sorted(names - set(data))
        if missing:
            raise SkillFileError(f"periodic MP is missing field(s) {missing}")
        unknown = sorted(set(data) - names - {"kind", "version"})
        if unknown:
            raise SkillFileError(f"periodic MP has unknown field(s) {unknown}")
        kwargs = {name: _as_float(data[name], name, positive=name in _SCALARS_POSITIVE) for name in _SCALARS_POSITIVE}
        kwargs.update({name: _as_float(data[name], name, positive=False) for name in _SCALARS_ANY})
        kwargs.update({name: _as_array(data[name], name, ndim) for name, ndim in _ARRAYS})
        return cls(**kwargs)


# --------------------------------------------------------------------------- frequency and phase


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


def _validate_segment(t_s, y) -> tuple[np.ndarray, np.ndarray]:
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


def _checked_phase_fit(t, y, follow_drift=True) -> _PhaseFit:
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
    t, y = _validate_segment(t_s, y)
    fit = _checked_phase_fit(t, y)
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
    t, y = _validate_segment(t_s, y)
    return _checked_phase_fit(t, y, follow_drift).phase(t)


# --------------------------------------------------------------------------- learning


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
    t, y = _validate_segment(t_s, y)
    fit = _checked_phase_fit(t, y, follow_drift)
    phase_span = float(fit.phase(t[-1]) - fit.phase(t[0]))
    omega = phase_span / (t[-1] - t[0])

    # The GMM sees a uniform resampling (cubic spline) of at least 30 samples per
    # component: short, fast segments (100 samples) are upsampled, long ones
    # decimated to MAX_GMM_SAMPLES.
    n_gmm = int(np.clip(len(t), GMM_SAMPLES_PER_COMPONENT * n_components, MAX_GMM_SAMPLES))
    t_u = np.linspace(t[0], t[-1], n_gmm)
    y_u = CubicSpline(t, y, axis=0)(t_u)
    n_comp = max(MIN_COMPONENTS, min(int(n_components), n_gmm // 10))
    grid, template, _ = periodic_template(fit.phase(t_u), y_u, n_template, n_comp, seed=seed)

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
        phase_start_rad=float(fit.phase(t[0]) % TWO_PI),
        phase_end_rad=float(fit.phase(t[-1]) % TWO_PI),
        n_cycles=phase_span / TWO_PI,
    )


# --------------------------------------------------------------------------- step API


class PeriodicStatus(IntEnum):
    """Result of :meth:`PeriodicRunner.update` (ruckig style: negative = error)."""

    WORKING = 0
    ERROR_INVALID_INPUT = -100


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


class PeriodicRunner:
    """Runs a periodic DMP at a fixed control rate, ruckig style.

    Build once, then call :meth:`update` every cycle; read
    :attr:`position_m`, :attr:`velocity_m_s`, :attr:`acceleration_m_s2`
    (arrays of shape (n_dims,), overwritten in place: copy to keep) and
    :attr:`phase_rad`. :meth:`set_targets` moves y_m, r and Omega to new
    values through critically damped filters of time constant
    ``ramp_time_constant_s`` (0 = jump at once).

    Parameters
    ----------
    mp : PeriodicMP
    anchor_m : array, shape (n_dims,), optional
        y_m [m]; default ``mp.anchor_m``.
    amplitude_m : float, optional
        r [m]; default ``mp.amplitude_m``.
    omega_rad_s : float, optional
        Omega [rad/s]; default ``mp.omega_rad_s``.
    start_phase_rad : float, optional
        Initial phase [rad]; default ``mp.phase_start_rad``.
    start_position_m, start_velocity_m_s : arrays, shape (n_dims,), optional
        Initial state [m], [m/s]; each defaults to the limit cycle at the start phase.
    ramp_time_constant_s : float
        Time constant of the parameter filters [s], >= 0.

    Attributes
    ----------
    position_m, velocity_m_s, acceleration_m_s2 : arrays, shape (n_dims,)
        State after the last update [m], [m/s], [m/s^2] (views, overwritten in place).
    phase_rad : float
        Phase in [0, 2 pi) [rad]; ``cycles`` counts the wraps and
        ``phase_unwrapped_rad`` = cycles * 2 pi + phase_rad.
    time_s : float
        Time integrated since construction [s].
    calculation_duration_us : float
        Wall time of the last update [us].

    Raises
    ------
    PlanningError
        Invalid execution parameters (at construction only).
    """

    def __init__(
        self,
        mp: PeriodicMP,
        anchor_m: np.ndarray | None = None,
        amplitude_m: float | None = None,
        omega_rad_s: float | None = None,
        start_phase_rad: float | None = None,
        *,
        start_position_m: np.ndarray | None = None,
        start_velocity_m_s: np.ndarray | None = None,
        ramp_time_constant_s: float = DEFAULT_RAMP_TIME_CONSTANT_S,
    ) -> None:
        anchor, amp, omega = _check_execution_params(mp, anchor_m, amplitude_m, omega_rad_s)
        phase = mp.phase_start_rad if start_phase_rad is None else float(start_phase_rad)
        if not math.isfinite(phase):
            raise PlanningError(f"start_phase_rad must be finite, got {start_phase_rad!r}")
        tau = float(ramp_time_constant_s)
        if not (math.isfinite(tau) and tau >= 0):
            raise PlanningError(f"ramp_time_constant_s must be finite and >= 0 s, got {ramp_time_constant_s!r}")
        n = mp.n_dims
        pos0, vel0, _ = _periodic_state_impl(mp._stacked, np.asarray(phase % TWO_PI), anchor, amp, omega)
        for name, value in (("start_position_m", start_position_m), ("start_velocity_m_s", start_velocity_m_s)):
            if value is not None and (np.shape(value) != (n,) or not np.isfinite(value).all()):
                raise PlanningError(f"{name} must be a finite array of shape ({n},), got {value!r}")
        if start_position_m is not None:
            pos0 = np.asarray(start_position_m, dtype=float)
        if start_velocity_m_s is not None:
            vel0 = np.asarray(start_velocity_m_s, dtype=float)

        self.mp = mp
        self.n_dims = n
        self._alpha, self._beta = mp.alpha, mp.beta
        # Forcing, eq. (4): [cos phi, sin phi, 1] @ H = h (cos(phi - c) - 1), then
        # exp, then psi @ [W | 1] gives numerator and denominator in one product.
        self._cs = np.array([0.0, 0.0, 1.0])
        self._h3 = np.ascontiguousarray(
            np.stack([mp.widths * np.cos(mp.centres_rad), mp.widths * np.sin(mp.centres_rad), -mp.widths])
        )
        self._w1 = np.ascontiguousarray(np.column_stack([mp.weights, np.ones(mp.n_basis)]))
        self._psi = np.empty(mp.n_basis)
        self._num = np.empty(n + 1)
        self._omega_f = 0.0 if tau == 0 else 1.0 / tau
        # Effective parameters and their filters. Columns: y_m (n), r, Omega;
        # targets (n + 2,); filter state rows: error (value - target), rate.
        self._ym = anchor.copy()
        self._r, self._omega = amp, omega
        self._targets = np.concatenate([anchor, [amp, omega]])
        self._ev = np.zeros((2, n + 2))
        self._ev_next = np.zeros((2, n + 2))
        self._filter_map = np.empty((2, 2))
        self._filter_dt = math.nan
        self._delta = np.empty(n)
        self._settle_countdown = 0
        self._ramping = False
        # State, double-buffered, rows: x1 = y1 - y_m, x2 = y2, F(phi) (r = 1), dF over the step.
        self._z = np.zeros((4, n))
        self._z_next = np.zeros((4, n))
        self._z[0] = pos0 - anchor
        self._z[1] = vel0 / omega
        # Step map [Phi | r g0 | r g1] (2, 4) and output map (3, 3), rebuilt when a, r or Omega change.
        self._step = np.empty((2, 4))
        self._step_key = (math.nan, math.nan)
        self._out_map = np.zeros((3, 3))
        self._out_map[0, 0] = 1.0
        self._out_key = (math.nan, math.nan)
        # Outputs, rows: position [m], velocity [m/s], acceleration [m/s^2].
        self._out = np.empty((3, n))
        self.position_m = self._out[0]
        self.velocity_m_s = self._out[1]
        self.acceleration_m_s2 = self._out[2]
        self.phase_rad = phase % TWO_PI
        self.cycles = int(phase // TWO_PI)
        self.time_s = 0.0
        self.calculation_duration_us = 0.0
        self._forcing_into(self.phase_rad, self._z[2])
        self._write_outputs(self._z)

    # -- effective parameters (read only)
    @property
    def anchor_m(self) -> np.ndarray:
        """Effective y_m [m], shape (n_dims,) (a copy)."""
        return self._ym.copy()

    @property
    def amplitude_m(self) -> float:
        """Effective r [m]."""
        return self._r

    @property
    def omega_rad_s(self) -> float:
        """Effective Omega [rad/s]."""
        return self._omega

    @property
    def is_ramping(self) -> bool:
        """True while y_m, r or Omega still move toward their targets."""
        return self._ramping

    @property
    def phase_unwrapped_rad(self) -> float:
        """Phase since the start, not wrapped [rad]."""
        return self.cycles * TWO_PI + self.phase_rad

    def set_targets(
        self, *, anchor_m: np.ndarray | None = None, amplitude_m: float | None = None, omega_rad_s: float | None = None
    ) -> PeriodicStatus:
        """New targets for y_m [m] (n_dims,), r [m], Omega [rad/s]; None keeps a target.

        Returns ERROR_INVALID_INPUT (and changes nothing) for a wrong shape,
        a non-finite value or a non-positive amplitude / frequency.
        """
        if anchor_m is not None:
            anchor = np.asarray(anchor_m, dtype=float)
            if anchor.shape != (self.n_dims,) or not np.isfinite(anchor).all():
                return PeriodicStatus.ERROR_INVALID_INPUT
        for value in (amplitude_m, omega_rad_s):
            if value is not None and not (math.isfinite(value) and value > 0):
                return PeriodicStatus.ERROR_INVALID_INPUT
        n, targets = self.n_dims, self._targets
        if anchor_m is not None:
            targets[:n] = anchor
        if amplitude_m is not None:
            targets[n] = float(amplitude_m)
        if omega_rad_s is not None:
            targets[n + 1] = float(omega_rad_s)
        if self._omega_f == 0.0:  # no ramp: jump now
            self._snap_to_targets()
        else:
            self._ev[0, :n] = self._ym - targets[:n]
            self._ev[0, n] = self._r - targets[n]
            self._ev[0, n + 1] = self._omega - targets[n + 1]
            self._ramping = True
        return PeriodicStatus.WORKING

    def update(self, dt_s: float) -> PeriodicStatus:
        """Advance eqs. (1)-(3) by ``dt_s`` (0 < dt_s <= MAX_DT_S) and refresh the outputs."""
        t0 = time.perf_counter_ns()
        if not 0.0 < dt_s <= MAX_DT_S:
            return PeriodicStatus.ERROR_INVALID_INPUT
        if self._ramping:
            self._advance_filters(dt_s)
        a = self._omega * dt_s
        r = self._r
        if a != self._step_key[0] or r != self._step_key[1]:
            p11, p12, g01, g11, p21, p22, g02, g12 = _step_coefficients(a, self._alpha, self._beta)
            m = self._step
            m[0, 0], m[0, 1], m[0, 2], m[0, 3] = p11, p12, r * g01, r * g11
            m[1, 0], m[1, 1], m[1, 2], m[1, 3] = p21, p22, r * g02, r * g12
            self._step_key = (a, r)
        phase = self.phase_rad + a
        if phase >= TWO_PI:
            wraps = int(phase // TWO_PI)
            phase -= wraps * TWO_PI
            self.cycles += wraps
        self.phase_rad = phase
        z, z_next = self._z, self._z_next
        self._forcing_into(phase, z_next[2])
        np.subtract(z_next[2], z[2], out=z[3])
        np.matmul(self._step, z, out=z_next[:2])
        self._z, self._z_next = z_next, z
        self._write_outputs(z_next)
        self.time_s += dt_s
        self.calculation_duration_us = (time.perf_counter_ns() - t0) * 1e-3
        return PeriodicStatus.WORKING

    def _forcing_into(self, phase: float, out: np.ndarray) -> None:
        """Eq. (4) with r = 1 at ``phase`` into ``out`` (n,), without allocating."""
        cs, psi, num = self._cs, self._psi, self._num
        cs[0] = math.cos(phase)
        cs[1] = math.sin(phase)
        np.dot(cs, self._h3, out=psi)
        np.exp(psi, out=psi)
        np.dot(psi, self._w1, out=num)
        np.divide(num[:-1], num[-1], out=out)

    def _write_outputs(self, z: np.ndarray) -> None:
        """[pos - y_m, vel, acc] = [[1, 0, 0], [0, W, 0], [-ab W^2, -a W^2, r W^2]] @ (x1, x2, F)."""
        om, r = self._omega, self._r
        if om != self._out_key[0] or r != self._out_key[1]:
            om2, m = om * om, self._out_map
            m[1, 1] = om
            m[2, 0], m[2, 1], m[2, 2] = -self._alpha * self._beta * om2, -self._alpha * om2, r * om2
            self._out_key = (om, r)
        np.matmul(self._out_map, z[:3], out=self._out)
        self.position_m += self._ym

    def _advance_filters(self, dt: float) -> None:
        """Exact step of the critically damped filters e'' = -w^2 e - 2 w e' (e = value - target).

        ``e(t) = (e0 + g t) exp(-w t)``, ``e'(t) = (e0' - w g t) exp(-w t)``, ``g = e0' + w e0``:
        one (2, 2) map applied to every column (y_m per dimension, r, Omega).
        """
        w = self._omega_f
        if dt != self._filter_dt:
            d = math.exp(-w * dt)
            self._filter_map[:] = [[d * (1.0 + w * dt), d * dt], [-d * w * w * dt, d * (1.0 - w * dt)]]
            self._filter_dt = dt
        ev, ev_next, n = self._ev, self._ev_next, self.n_dims
        np.matmul(self._filter_map, ev, out=ev_next)
        # y_m moves by delta; x1 = y1 - y_m shifts so that y1 does not move.
        np.subtract(ev_next[0, :n], ev[0, :n], out=self._delta)
        self._ym += self._delta
        self._z[0] -= self._delta
        self._r = float(self._targets[n] + ev_next[0, n])
        self._omega = float(self._targets[n + 1] + ev_next[0, n + 1])
        self._ev, self._ev_next = ev_next, ev
        self._settle_countdown -= 1
        if self._settle_countdown <= 0:
            self._settle_countdown = 32
            scale = self._targets[n]  # amplitude for y_m and r, Omega for Omega
            err = np.abs(ev_next[0]) + np.abs(ev_next[1]) / w
            if err[: n + 1].max() < 1e-9 * scale and err[n + 1] < 1e-9 * self._targets[n + 1]:
                self._snap_to_targets()

    def _snap_to_targets(self) -> None:
        n, targets = self.n_dims, self._targets
        self._z[0] -= targets[:n] - self._ym
        self._ym[:] = targets[:n]
        self._r, self._omega = float(targets[n]), float(targets[n + 1])
        self._ev[:] = 0.0
        self._ramping = False


class Rollout(NamedTuple):
    """Sampled run of a periodic DMP.

    t_s : array, shape (K,) [s]; position_m, velocity_m_s, acceleration_m_s2 :
    arrays, shape (K, n_dims); phase_rad : array, shape (K,), unwrapped [rad].
    """

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray
    phase_rad: np.ndarray


def rollout(mp: PeriodicMP, duration_s: float, dt_s: float = 1e-3, **runner_kwargs) -> Rollout:
    """Integrate eqs. (1)-(3) with :class:`PeriodicRunner` for ``duration_s``.

    Parameters
    ----------
    mp : PeriodicMP
    duration_s : float
        Length [s] (> 0).
    dt_s : float
        Step [s], in (0, MAX_DT_S].
    **runner_kwargs
        Passed to :class:`PeriodicRunner` (anchor_m, amplitude_m, omega_rad_s,
        start_phase_rad, start_position_m, start_velocity_m_s).

    Returns
    -------
    Rollout
        K = round(duration_s / dt_s) + 1 samples, the first being the initial state.
    """
    if not (math.isfinite(duration_s) and duration_s > 0 and 0 < dt_s <= MAX_DT_S):
        raise PlanningError(f"need duration_s > 0 and 0 < dt_s <= {MAX_DT_S}; got {duration_s!r}, {dt_s!r}")
    runner = PeriodicRunner(mp, **runner_kwargs)
    k = int(round(duration_s / dt_s)) + 1
    n = mp.n_dims
    pos, vel, acc = np.empty((k, n)), np.empty((k, n)), np.empty((k, n))
    phase = np.empty(k)
    for i in range(k):
        if i:
            runner.update(dt_s)
        pos[i], vel[i], acc[i] = runner.position_m, runner.velocity_m_s, runner.acceleration_m_s2
        phase[i] = runner.phase_unwrapped_rad
    return Rollout(np.arange(k) * dt_s, pos, vel, acc, phase)
