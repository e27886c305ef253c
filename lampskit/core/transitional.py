"""Third-order transitional movement primitives, paper eqs. (7)-(19).

A transitional MP carries the tool from the state where one periodic MP
stops, ``(y0, v0, a0)``, into the entry state of the next one,
``(g1, g2, g3)``, in a chosen duration ``T``, with position, velocity and
acceleration continuous at both junctions. The derivation of the consistent
form implemented here is in ``docs/transitional_mp.md``; in short:

* ``tau = T``, time runs as ``s = t / T`` in [0, 1] and the state is scaled,
  ``Y = (y, T dy/dt, T^2 d2y/dt2)``, so eqs. (8)-(9) hold and one learned MP
  plays at any duration. The phase is ``x = exp(-lambda s)`` (eq. 12).
* The crossing target ``r(t)`` is the entry state's constant-acceleration
  extrapolation ``g1 + g2 u + g3 u^2 / 2`` (``u = t - T``; eqs. 14-17 with
  the sign of (17) corrected), multiplied by a Gaussian window of width
  ``sigma`` so the target stays within about ``crossing_reach_m`` of ``g1``
  (``crossing_reach_m = inf`` gives the paper's unwindowed target).
  ``r(T), r'(T), r''(T) = g1, g2, g3`` exactly.
* Eq. (13) with ``(g1hat, g2hat, g3) = (r, T r', T^2 r'')`` plus the target's
  jerk ``T^3 r'''`` as feed-forward (zero for the paper's constant-acceleration
  target) is, for ``e = Y - R``::

      de1/ds = e2,  de2/ds = e3,
      de3/ds = -(1 - x) (p^3 e1 + 3 p^2 e2 + 3 p e3) + f(x)       (eq. 19 gains)

  a linear system whose solution is ``Phi(s) e(0)`` plus the response to the
  forcing term. Both are tabulated once per learned MP (RK4 on
  :data:`N_TABLE` steps, normalised time, so valid for every ``T``).
* The residual ``e(1)`` is therefore known when a transition is built, and a
  quintic ``c(s) = a3 s^3 + a4 s^4 + a5 s^5`` (zero position, velocity and
  acceleration at s = 0) cancels it: the transition lands exactly on
  ``(g1, g2, g3)``. ``y(0) = (y0, v0, a0)`` holds by construction.

At run time a transition is ``target(t) + e(s) + c(s)``: an analytic target,
one cubic-Hermite interpolation of the MP's tables and no integration, so
the cost per 1 kHz step is a few microseconds and independent of the number
of basis functions, and any ``dt`` gives the same (exact) trajectory.

Learning (:func:`learn_transitional`) fits the weights of eq. (10) so that the
generated transition replays the demonstrated positions (least squares, the
default) or, classically, fits the forcing target of eq. (13) by locally
weighted regression.

Public API: :class:`TransitionalMP` (``to_dict`` / ``from_dict``);
:func:`plan_transition` -> :class:`TransitionPlan`, :func:`evaluate`,
:func:`rollout` -> :class:`TrajectorySamples`; :func:`similarity_transform`
for the ``forcing_transform``. Learning is in :mod:`.transitional_fit`
(:func:`learn_transitional`), the 1 kHz step API in
:mod:`.transitional_runner` (:class:`TransitionalRunner`,
``update(dt_s) -> TransitionStatus``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, NamedTuple

import numpy as np

from lampskit.core.transitional_maths import CORRECTION_TABLE, fundamental_tables, hermite_table
from lampskit.errors import SkillFileError

#: Format tag and version written by :meth:`TransitionalMP.to_dict`.
KIND = "transitional_mp"
VERSION = 1
#: A segment needs at least this many samples and this duration [s] to be learned.
MIN_SAMPLES = 10
MIN_DURATION_S = 0.1

#: Defaults (see docs/transitional_mp.md, "Choosing p, lambda and the window").
DEFAULT_P = 20.0
DEFAULT_LAMBDA = 8.0
DEFAULT_N_BASIS = 40
DEFAULT_REACH_M = 0.1


class TransitionStatus(IntEnum):
    """Result of :meth:`TransitionalRunner.update` (ruckig style: negative = error)."""

    ERROR_INVALID_INPUT = -100
    WORKING = 0
    FINISHED = 1


class TrajectorySamples(NamedTuple):
    """A sampled trajectory, shared by the MP and the baselines.

    Attributes
    ----------
    t_s : array, shape (m,)
        Sample times from the transition start [s].
    position_m, velocity_m_s, acceleration_m_s2 : arrays, shape (m, n_dims)
    """

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray


# --------------------------------------------------------------------------
# maths on arrays


# --------------------------------------------------------------------------
# the learned primitive


@dataclass(frozen=True, eq=False)
class TransitionalMP:
    """A learned third-order transitional MP (paper eqs. 7-19).

    Attributes
    ----------
    weights : array, shape (N, n_dims)
        Forcing-term weights ``w_i`` of eq. (10), normalised jerk units, in
        the demonstration's frame.
    centres : array, shape (N,)
        Basis centres ``c_i`` in phase, eq. (11).
    widths : array, shape (N,)
        Basis widths ``h_i``, eq. (11).
    p : float
        Pole of eq. (19): ``P(s) = (s + p / T)^3``; dimensionless (per
        duration), in [1, 60].
    lambda_ : float
        Phase decay of eq. (12), ``x = exp(-lambda t / T)``, in [0.1, 30].
    crossing_reach_m : float
        Bound on how far the crossing target strays from ``g1`` [m]
        (``inf``: the paper's unwindowed target).
    demo_duration_s : float
        Duration of the demonstrated segment [s].
    demo_start : array, shape (3, n_dims)
        Demonstrated start state: position [m], velocity [m/s], acceleration [m/s^2].
    demo_goal : array, shape (3, n_dims)
        Demonstrated end state, same rows.
    demo_displacement_m : array, shape (n_dims,)
        ``demo_goal[0] - demo_start[0]``.
    demo_rmse_m : float
        RMS position error of the MP replaying its own demonstration [m].
    table_end, table : arrays, derived (not stored in the skill file)
        The fundamental solutions, the forcing responses and the terminal
        correction (columns ``3 + N + 3``) at ``s = 1``, shape (3, cols), and
        as the per-interval cubic-Hermite table the runners interpolate,
        shape (N_TABLE, 12 cols): :func:`~lampskit.core.transitional_maths.hermite_table`.

    Raises
    ------
    SkillFileError
        A field has the wrong shape, is not finite, or is out of range.
    """

    weights: np.ndarray
    centres: np.ndarray
    widths: np.ndarray
    p: float
    lambda_: float
    crossing_reach_m: float
    demo_duration_s: float
    demo_start: np.ndarray
    demo_goal: np.ndarray
    demo_displacement_m: np.ndarray
    demo_rmse_m: float = 0.0
    table_end: np.ndarray = field(init=False, repr=False, compare=False)
    table: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("p", "lambda_", "crossing_reach_m", "demo_duration_s", "demo_rmse_m"):
            object.__setattr__(self, name, _scalar_field(name, getattr(self, name)))
        w = _array_field("weights", self.weights, 2)
        n_basis, n = w.shape
        if n_basis < 2 or n < 1:
            raise SkillFileError(f"TransitionalMP.weights: need shape (N >= 2, n_dims >= 1), got {w.shape}")
        c = _array_field("centres", self.centres, 1, (n_basis,))
        h = _array_field("widths", self.widths, 1, (n_basis,))
        if np.any(h <= 0):
            raise SkillFileError("TransitionalMP.widths: every width must be > 0")
        for name, value, lo, hi in (("p", self.p, 1.0, 60.0), ("lambda_", self.lambda_, 0.1, 30.0)):
            if not lo <= value <= hi:
                raise SkillFileError(f"TransitionalMP.{name}: must be in [{lo}, {hi}], got {value!r}")
        if not self.crossing_reach_m > 0:
            raise SkillFileError(
                f"TransitionalMP.crossing_reach_m: must be > 0 (inf allowed), got {self.crossing_reach_m!r}"
            )
        if not (math.isfinite(self.demo_duration_s) and self.demo_duration_s > 0):
            raise SkillFileError(
                f"TransitionalMP.demo_duration_s: must be finite and > 0, got {self.demo_duration_s!r}"
            )
        if not (math.isfinite(self.demo_rmse_m) and self.demo_rmse_m >= 0):
            raise SkillFileError(f"TransitionalMP.demo_rmse_m: must be finite and >= 0, got {self.demo_rmse_m!r}")
        start = _array_field("demo_start", self.demo_start, 2, (3, n))
        goal = _array_field("demo_goal", self.demo_goal, 2, (3, n))
        disp = _array_field("demo_displacement_m", self.demo_displacement_m, 1, (n,))
        for name, array in (("weights", w), ("centres", c), ("widths", h), ("demo_start", start),
                            ("demo_goal", goal), ("demo_displacement_m", disp)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        phi, forced = fundamental_tables(self.p, self.lambda_, w, c, h)
        end, hermite = hermite_table(np.concatenate([phi, forced, CORRECTION_TABLE], axis=2))
        object.__setattr__(self, "table_end", end)
        object.__setattr__(self, "table", hermite)

    @property
    def n_dims(self) -> int:
        return self.weights.shape[1]

    @property
    def n_basis(self) -> int:
        return self.weights.shape[0]

    def to_dict(self) -> dict:
        """Plain-JSON description (lists and floats); ``inf`` reach is written as the string ``"inf"``."""
        return {
            "kind": KIND,
            "version": VERSION,
            "weights": self.weights.tolist(),
            "centres": self.centres.tolist(),
            "widths": self.widths.tolist(),
            "p": self.p,
            "lambda": self.lambda_,
            "crossing_reach_m": "inf" if math.isinf(self.crossing_reach_m) else self.crossing_reach_m,
            "demo_duration_s": self.demo_duration_s,
            "demo_start": self.demo_start.tolist(),
            "demo_goal": self.demo_goal.tolist(),
            "demo_displacement_m": self.demo_displacement_m.tolist(),
            "demo_rmse_m": self.demo_rmse_m,
        }

    @classmethod
    def from_dict(cls, d: object) -> TransitionalMP:
        """Inverse of :meth:`to_dict`; raises :class:`SkillFileError` naming the bad field."""
        if not isinstance(d, dict):
            raise SkillFileError(f"transitional MP: expected an object, got {type(d).__name__}")
        if d.get("kind", KIND) != KIND:
            raise SkillFileError(f"transitional MP: kind must be {KIND!r}, got {d.get('kind')!r}")
        if d.get("version", VERSION) != VERSION:
            raise SkillFileError(
                f"transitional MP: unsupported version {d.get('version')!r} (this code reads {VERSION})"
            )
        keys = ("weights", "centres", "widths", "p", "lambda", "crossing_reach_m", "demo_duration_s",
                "demo_start", "demo_goal", "demo_displacement_m")
        missing = [k for k in keys if k not in d]
        if missing:
            raise SkillFileError(f"transitional MP: missing field(s) {missing}")
        scalars = ("p", "lambda", "crossing_reach_m", "demo_duration_s", "demo_rmse_m")
        values = {}
        for k in keys + ("demo_rmse_m",):
            if k not in d:
                continue
            raw = d[k]
            if k in scalars:
                if k == "crossing_reach_m" and raw == "inf":
                    raw = math.inf
                if isinstance(raw, bool) or not isinstance(raw, (int, float)):
                    raise SkillFileError(f"TransitionalMP.{k}: expected a number, got {raw!r:.80}")
                raw = float(raw)
            values[k] = raw
        values["lambda_"] = values.pop("lambda")
        return cls(**values)


def _scalar_field(name: str, value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SkillFileError(f"TransitionalMP.{name}: expected a number, got {value!r:.80}") from None


def _array_field(name: str, value: object, ndim: int, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SkillFileError(f"TransitionalMP.{name}: not an array of numbers") from None
    if a.ndim != ndim or (shape is not None and a.shape != shape):
        want = shape if shape is not None else f"{ndim}-D"
        raise SkillFileError(f"TransitionalMP.{name}: expected shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SkillFileError(f"TransitionalMP.{name}: contains NaN or inf; every value must be finite")
    return a


# --------------------------------------------------------------------------
# generalisation: one transition
