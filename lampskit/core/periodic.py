"""Periodic dynamic movement primitives, paper eqs. (1)-(6).

The periodic DMP (Sec. II-C), with ``y1`` the position and ``y2`` the
velocity divided by the frequency::

    dy2/dt = Omega * (alpha * (beta * (y_m - y1) - y2) + f(phi))        (1)
    dy1/dt = Omega * y2                                                 (2)
    dphi/dt = Omega            (eq. (3) with tau = 1 / Omega, phi in rad)
    f(phi) = r * sum_i w_i psi_i(phi) / sum_i psi_i(phi)                (4)
    psi_i(phi) = exp(h_i * (cos(phi - c_i) - 1))                        (5)
    f_d = ydd / Omega^2 - alpha * (beta * (y_m - y) - yd / Omega)       (6)

Closed form (:func:`periodic_state`)
------------------------------------
With ``y1 = y_m + r s(phi)`` eqs. (1)-(2) become the linear ODE
``s'' + alpha s' + alpha beta s = F(phi)``, ``F = sum w psi / sum psi``. Its
periodic steady state (the limit cycle) is exact in Fourier space:
``S_k = F_k / (-k^2 + i alpha k + alpha beta)``. We sample F on a grid fine
enough for the basis bandwidth, FFT, divide, and keep the harmonics above
1e-13 of the largest. Position, velocity and acceleration at any phase are
``y_m + r s``, ``Omega r s'``, ``Omega^2 r s''``.

Learning (frequency, phase, GMM-GMR template, weights): :mod:`lampskit.learn.periodic_fit`.
Execution: :mod:`lampskit.core.periodic_runner`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lampskit.errors import PlanningError, SkillFileError

TWO_PI = 2.0 * math.pi
DEFAULT_ALPHA = 25.0
DEFAULT_N_BASIS = 50
#: Height at which neighbouring basis functions cross (sets the widths h).
BASIS_CROSSING = 0.8
SKILL_KIND = "periodic_dmp"
SKILL_VERSION = 1


# --------------------------------------------------------------------------- basis, eqs. (4)-(5)


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
    mp: PeriodicMP,
    phase_rad: np.ndarray | float,
    anchor_m: np.ndarray | None = None,
    amplitude_m: float | None = None,
    omega_rad_s: float | None = None,
    stroke: np.ndarray | None = None,
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
    stroke : array, shape (n_dims, n_dims), optional
        A linear map of the cycle about y_m (stretch and turn, :func:`stroke_matrix`); default the identity.

    Returns
    -------
    pos, vel, acc : arrays, shape (n_dims,) for a scalar phase, else (P, n_dims)
        In [m], [m/s], [m/s^2].

    Raises
    ------
    PlanningError
        Non-finite phase, wrong anchor shape, non-positive amplitude or frequency.
    """
    anchor, amp, omega = check_execution_params(mp, anchor_m, amplitude_m, omega_rad_s)
    phase = np.asarray(phase_rad, dtype=float)
    if phase.ndim > 1 or not np.isfinite(phase).all():
        raise PlanningError(f"phase_rad must be a finite scalar or 1-D array, got shape {phase.shape}")
    if stroke is not None:
        stroke = check_stroke(stroke, mp.n_dims)
    return periodic_state_unchecked(mp.limit_cycle, phase, anchor, amp, omega, stroke)


def periodic_state_unchecked(limit_cycle, phase, anchor, amp, omega, stroke=None):
    """:func:`periodic_state` without checks, for the runners' hot path.

    ``limit_cycle`` is :attr:`PeriodicMP.limit_cycle`, (K+1, 3 n_dims) complex;
    ``phase`` [rad] a scalar or (P,) array; ``anchor`` (n_dims,) [m]; ``amp``
    [m]; ``omega`` [rad/s]; ``stroke`` (n_dims, n_dims) or None. Returns
    position, velocity, acceleration as there.
    """
    stacked = limit_cycle
    n = stacked.shape[1] // 3
    k = np.arange(stacked.shape[0])
    e = np.exp(1j * np.multiply.outer(phase, k))
    out = (e @ stacked).real
    s, ds, dds = out[..., :n], out[..., n : 2 * n], out[..., 2 * n :]
    if stroke is not None:  # eqs. (1)-(2) are linear: a constant map of the forcing maps the whole cycle
        s, ds, dds = s @ stroke.T, ds @ stroke.T, dds @ stroke.T
    return anchor + amp * s, (omega * amp) * ds, (omega * omega * amp) * dds


#: A stroke may stretch the learned cycle at most this much along any direction.
MAX_STROKE_GAIN = 4.0


def check_stroke(stroke, n_dims: int) -> np.ndarray:
    """``stroke`` as a finite (n_dims, n_dims) array of spectral norm in (0, MAX_STROKE_GAIN]; PlanningError if not."""
    S = np.asarray(stroke, dtype=float)
    if S.shape != (n_dims, n_dims) or not np.isfinite(S).all():
        raise PlanningError(f"stroke must be a finite ({n_dims}, {n_dims}) matrix, got {stroke!r}")
    gain = float(np.linalg.norm(S, 2))
    if not 0.0 < gain <= MAX_STROKE_GAIN:
        raise PlanningError(f"stroke must stretch by (0, {MAX_STROKE_GAIN}], its norm is {gain:.3g}")
    return S


def rotation_2d(angle_rad: float) -> np.ndarray:
    """(2, 2) rotation by ``angle_rad`` [rad]."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s], [s, c]])


def stroke_matrix(cycle_axis_rad: float, target_axis_rad: float, across: float) -> np.ndarray:
    """The (2, 2) stroke turning a cycle's main axis (``cycle_axis_rad``) onto ``target_axis_rad`` [rad] (both in
    the board plane) and scaling the cycle across its main axis by ``across`` (> 0): ``R(target) diag(1, across)
    R(cycle)^T``. Spectral norm max(1, across); the identity for equal axes and ``across`` 1."""
    if not (math.isfinite(across) and 0.0 < across <= MAX_STROKE_GAIN):
        raise PlanningError(f"across must be in (0, {MAX_STROKE_GAIN}], got {across!r}")
    return rotation_2d(target_axis_rad) @ np.diag([1.0, across]) @ rotation_2d(cycle_axis_rad).T


def cycle_shape(mp: PeriodicMP, samples: int = 360) -> tuple[float, float]:
    """(main axis [rad] in (-pi/2, pi/2], aspect in (0, 1]) of ``mp``'s limit cycle (2-D): the direction of
    largest spread of its positions and the ratio of its extents across and along that direction."""
    if mp.n_dims != 2:
        raise PlanningError(f"a cycle's shape needs a 2-D MP, this one has {mp.n_dims} dimensions")
    pos, _, _ = periodic_state_unchecked(mp.limit_cycle, np.linspace(0.0, TWO_PI, samples, endpoint=False),
                                         np.zeros(2), 1.0, 1.0)
    pos = pos - pos.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov(pos.T))
    main = vecs[:, -1]
    along, across = np.ptp(pos @ main), np.ptp(pos @ vecs[:, 0])
    axis = math.atan2(main[1], main[0])
    if axis <= -math.pi / 2:
        axis += math.pi
    elif axis > math.pi / 2:
        axis -= math.pi
    return axis, float(np.clip(across / max(along, 1e-12), 1e-3, 1.0))


def check_execution_params(mp, anchor_m, amplitude_m, omega_rad_s):
    """(anchor (n_dims,) [m], r [m], Omega [rad/s]) to execute ``mp`` with; None takes the MP's own.

    Raises PlanningError naming the bad value.
    """
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
    limit_cycle: np.ndarray = field(init=False, repr=False)

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
        object.__setattr__(self, "limit_cycle", stacked)

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
    def from_dict(cls, data: dict) -> PeriodicMP:
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
        kwargs: dict[str, Any] = {name: _as_float(data[name], name, positive=name in _SCALARS_POSITIVE)
                                  for name in _SCALARS_POSITIVE}
        kwargs.update({name: _as_float(data[name], name, positive=False) for name in _SCALARS_ANY})
        kwargs.update({name: _as_array(data[name], name, ndim) for name, ndim in _ARRAYS})
        return cls(**kwargs)
