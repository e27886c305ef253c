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

Execution: :mod:`.periodic_runner`. Frequency and phase estimation: :mod:`.periodic_phase`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from .errors import LearningError, PlanningError, SkillFileError
from .gmr import MIN_COMPONENTS, periodic_template
from .periodic_phase import MIN_OSCILLATION_M, TWO_PI, _checked_phase_fit, _validate_segment


DEFAULT_ALPHA = 25.0
DEFAULT_N_BASIS = 50
DEFAULT_N_COMPONENTS = 20
DEFAULT_N_TEMPLATE = 512
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
