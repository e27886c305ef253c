"""The planner's data (:mod:`lampskit.core.planner`): what it takes, a stain as perception reports it and the
planner's tunables, and what it gives, a plan of wipes (periodic MPs) and the spec of each transition."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lampskit.errors import PlanningError


@dataclass(frozen=True)
class Stain:
    """A stain on the board, as perception reports it: its shape, which the planner wipes, and what the executor
    knows of it (kappa, the ink left, a smear). The one type of a stain past the wire (perception's message is
    :class:`interfaces.messages.StainObservation`; :func:`controller.stains_in.stain_state` makes this of it).

    Attributes
    ----------
    id : int
        Stable stain id.
    centre_m : array, shape (2,)
        Centre in the board plane [m].
    size_m : float
        Extent of the stain [m] along its main axis (its larger side).
    width_m : float
        Extent across the main axis [m]; 0 = not known (taken as round).
    axis_rad : float
        Direction of the main axis in the board plane [rad] (from board x).
    kappa : bool
        Wiping it is complete (perception's completion flag; the planner never reads it).
    ink : Stain or None
        The shape of the ink that remains of it (None: not reported).
    smeared : bool
        Perception says passes no longer clean it, with ``remaining`` (fraction of its first sighting, [0, 1]) after
        ``passes`` passes.
    """

    id: int
    centre_m: np.ndarray
    size_m: float
    width_m: float = 0.0
    axis_rad: float = 0.0
    kappa: bool = False
    ink: Stain | None = None
    smeared: bool = False
    remaining: float = 1.0
    passes: int = 0

    def __post_init__(self) -> None:
        c = np.asarray(self.centre_m, dtype=float).reshape(-1)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise PlanningError(f"stain {self.id}: centre_m must be 2 finite numbers, got {self.centre_m!r}")
        if not (np.isfinite(self.size_m) and self.size_m > 0):
            raise PlanningError(f"stain {self.id}: size_m must be a positive number, got {self.size_m!r}")
        if not (np.isfinite(self.width_m) and self.width_m >= 0 and np.isfinite(self.axis_rad)):
            raise PlanningError(f"stain {self.id}: width_m must be >= 0 and axis_rad finite, got "
                                f"{self.width_m!r}, {self.axis_rad!r}")
        object.__setattr__(self, "centre_m", c)

    @property
    def aspect(self) -> float:
        """Width over size in (0, 1]; 1 when the width is not known."""
        return 1.0 if self.width_m <= 0 else float(np.clip(self.width_m / self.size_m, 1e-3, 1.0))


@dataclass(frozen=True)
class PlannerParams:
    """Tunables of the planner (SI units).

    Attributes
    ----------
    amplitude_fraction : float
        Periodic amplitude r as a fraction of the stain size.
    min_amplitude_m, max_amplitude_m : float
        Clamp of r [m].
    transition_speed_m_s : float or None
        Mean speed of a transition [m/s]; None = as demonstrated.
    min_transition_s : float
        Shortest transition [s].
    max_transition_speed_m_s : float
        Cap on a transition's mean speed [m/s]: far stains get longer
        transitions rather than faster ones.
    order : str
        ``"shortest"`` (reorder to shorten travel) or ``"given"``.
    max_speed_m_s, max_accel_m_s2, max_jerk_m_s3 : float
        Kinematic bounds of the planned in-plane reference [m/s, m/s^2,
        m/s^3]: below the controller's 0.6 m/s brake, and what an iiwa
        pressing an eraser takes smoothly (a demonstrated wipe peaks near
        2.5 m/s^2 and 40 m/s^3).
    max_transition_stretch : float
        A transition is lengthened at most this many times its planned
        duration to meet the bounds (boundary states that violate them
        cannot be met by any duration: the best one is kept and counted).
    adaptive : bool
        Shape each wipe to its stain and adapt it while wiping (see the
        module docstring, point 5); False (the default until adaptive wiping
        has run on the real-time real-robot path without a guard trip): the
        learned cycle scaled to the stain's size, set once per stain
        ("fixed" wiping).
    round_aspect : float
        With ``adaptive``, a stain (or ink) whose width over size is at
        least this is wiped with the learned, unstretched cycle.
    min_stroke_aspect : float
        The narrowest stroke: the cycle is squeezed across the main axis to
        no less than this share of its length.
    """

    amplitude_fraction: float = 0.5
    min_amplitude_m: float = 0.01
    max_amplitude_m: float = 0.15
    transition_speed_m_s: float | None = None
    min_transition_s: float = 0.6
    max_transition_speed_m_s: float = 0.8
    order: str = "shortest"
    max_speed_m_s: float = 0.5
    max_accel_m_s2: float = 4.0
    max_jerk_m_s3: float = 100.0
    max_transition_stretch: float = 4.0
    adaptive: bool = False
    round_aspect: float = 0.8
    min_stroke_aspect: float = 0.35

    def __post_init__(self) -> None:
        if not isinstance(self.adaptive, bool):
            raise PlanningError(f"adaptive must be true or false, got {self.adaptive!r}")
        if not 0.05 <= self.min_stroke_aspect <= self.round_aspect <= 1.0:
            raise PlanningError(f"need 0.05 <= min_stroke_aspect <= round_aspect <= 1, got "
                                f"{self.min_stroke_aspect!r}, {self.round_aspect!r}")
        for name, lo, hi in (("max_speed_m_s", 0.01, 2.0), ("max_accel_m_s2", 0.05, 50.0),
                             ("max_jerk_m_s3", 0.5, 5000.0), ("max_transition_stretch", 1.0, 20.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and lo <= v <= hi):
                raise PlanningError(f"{name} must be in [{lo}, {hi}], got {v!r}")
        if not 0 < self.amplitude_fraction <= 2:
            raise PlanningError(f"amplitude_fraction must be in (0, 2], got {self.amplitude_fraction}")
        if not 0 < self.min_amplitude_m <= self.max_amplitude_m:
            raise PlanningError(
                f"need 0 < min_amplitude_m <= max_amplitude_m, got {self.min_amplitude_m}, {self.max_amplitude_m}"
            )
        if self.transition_speed_m_s is not None and not 0.01 <= self.transition_speed_m_s <= 2.0:
            raise PlanningError(f"transition_speed_m_s must be in [0.01, 2] m/s, got {self.transition_speed_m_s}")
        if not 0.05 <= self.min_transition_s <= 10:
            raise PlanningError(f"min_transition_s must be in [0.05, 10] s, got {self.min_transition_s}")
        if not 0.01 <= self.max_transition_speed_m_s <= 2.0:
            raise PlanningError(
                f"max_transition_speed_m_s must be in [0.01, 2] m/s, got {self.max_transition_speed_m_s}")
        if self.order not in ("shortest", "given"):
            raise PlanningError(f"order must be 'shortest' or 'given', got {self.order!r}")


@dataclass(frozen=True)
class Wipe:
    """One periodic MP of the plan: which learned MP, where (anchor (2,) [m]), how big (r [m]), how fast (Omega
    [rad/s]) and, with adaptive wiping, its stroke (2, 2) (None: the learned cycle as it is)."""

    stain: Stain
    periodic_index: int
    anchor_m: np.ndarray
    amplitude_m: float
    omega_rad_s: float
    stroke: np.ndarray | None = None

    @property
    def stroke_gain(self) -> float:
        """How much the stroke stretches the cycle at most (its spectral norm; 1 without one)."""
        return 1.0 if self.stroke is None else float(np.linalg.norm(self.stroke, 2))


@dataclass(frozen=True)
class Plan:
    """The stains in visiting order with their periodic MPs."""

    wipes: tuple[Wipe, ...]
    params: PlannerParams = field(default_factory=PlannerParams)

    @property
    def order(self) -> tuple[int, ...]:
        return tuple(w.stain.id for w in self.wipes)


@dataclass(frozen=True)
class TransitionSpec:
    """Everything needed to start one transitional MP (all arrays shape (2,))."""

    transitional_index: int
    start: tuple[np.ndarray, np.ndarray, np.ndarray]
    goal: tuple[np.ndarray, np.ndarray, np.ndarray]
    duration_s: float
    entry_phase_rad: float
    forcing_transform: np.ndarray
    peaks: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: planned peak speed, accel., jerk [m/s, m/s^2, m/s^3]
    within_limits: bool = True  #: False: no duration up to the stretch limit met the bounds (the best was kept)
