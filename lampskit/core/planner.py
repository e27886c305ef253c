"""Run-time generalisation (paper section II-C): chain the learned MPs across a new board.

Given a skill, the stains a perception reports (centre and size in the
board plane) and the tool's current state, the planner

1. orders the stains to shorten the travel (exact for up to
   :data:`EXACT_ORDER_MAX` stains, nearest neighbour + 2-opt above),
2. picks for each stain the learned periodic MP whose amplitude is closest
   to the one the stain needs, re-anchored at the stain centre (``y_m``) and
   scaled to its size (``r = amplitude_fraction * size``, clamped),
3. builds each transition when it is needed (:func:`plan_transition`), from
   the state the tool really has at that moment into the next periodic MP
   at an *entry phase* chosen so the periodic motion continues the
   transition's direction, with (g1, g2, g3) taken from the periodic MP's
   closed form at that phase; the learned transitional MP whose
   demonstrated move is most alike is mapped onto the new move by a
   rotation and uniform scale of its forcing term.
4. keeps every MP inside the kinematic bounds (``max_speed_m_s``,
   ``max_accel_m_s2``, ``max_jerk_m_s3`` of the in-plane reference): a
   periodic MP's Omega is capped so its limit cycle's peak speed,
   acceleration and jerk at its amplitude stay within them
   (:func:`bounded_omega`), and a transition is lengthened until its
   closed-form trajectory does (:func:`bounded_duration`). Position,
   velocity and acceleration stay continuous at every junction: only
   durations and frequencies change, never the boundary states.
5. with ``adaptive`` on, shapes each wipe to its stain (:func:`wipe_shape`):
   the learned MP is picked by the stain's aspect as well as its size, and
   its cycle is stretched across and turned to the stain's main axis by a
   *stroke* (:func:`~lampskit.core.periodic.stroke_matrix`); while wiping,
   the executor moves anchor, r, stroke and Omega after the ink that
   remains (:func:`adapted_wipe`).

All positions here are in-plane board coordinates (x, y) [m]; the normal
direction belongs to the force controller. :func:`lampskit.core.rollout.rollout`
executes a plan at a fixed rate with a stand-in for kappa (a number of
cycles per stain) for the plots, tests and benchmarks; the controller's skill
executor calls the same :func:`plan_transition` with perception's kappa.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from lampskit.errors import PlanningError
from lampskit.core.periodic import cycle_shape, periodic_state, stroke_matrix
from lampskit.core.skill import Skill
from lampskit.core.transitional_plan import evaluate as evaluate_transition
from lampskit.core.transitional_plan import plan_transition as plan_transition_mp
from lampskit.core.transitional_plan import similarity_transform

#: Up to this many stains the visiting order is found by exhaustive search.
EXACT_ORDER_MAX = 7
#: Demonstrated transitions shorter than this [m] carry no usable direction.
MIN_DEMO_DISPLACEMENT_M = 0.02


@dataclass(frozen=True)
class Stain:
    """A stain on the board, as perception reports it.

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
    """

    id: int
    centre_m: np.ndarray
    size_m: float
    width_m: float = 0.0
    axis_rad: float = 0.0

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
            raise PlanningError(f"max_transition_speed_m_s must be in [0.01, 2] m/s, got {self.max_transition_speed_m_s}")
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


def plan(
    skill: Skill,
    stains: Sequence[Stain],
    start_position_m: np.ndarray,
    params: PlannerParams | None = None,
) -> Plan:
    """Order the stains and assign each a re-anchored, re-scaled periodic MP."""
    params = params or PlannerParams()
    if not stains:
        raise PlanningError("no stains to wipe")
    ids = [s.id for s in stains]
    if len(set(ids)) != len(ids):
        raise PlanningError(f"stain ids must be unique, got {ids}")
    start = np.asarray(start_position_m, dtype=float).reshape(-1)
    if start.shape != (2,) or not np.all(np.isfinite(start)):
        raise PlanningError(f"start_position_m must be 2 finite numbers, got {start_position_m!r}")
    ordered = list(stains) if params.order == "given" else order_stains(stains, start)
    amplitudes = np.array([e.mp.amplitude_m for e in skill.periodic])
    wipes = []
    for s in ordered:
        r = float(np.clip(params.amplitude_fraction * s.size_m, params.min_amplitude_m, params.max_amplitude_m))
        if params.adaptive:
            k, stroke = wipe_shape(skill, r, s.aspect, s.axis_rad, params)
            gain = float(np.linalg.norm(stroke, 2)) if stroke is not None else 1.0
        else:
            k, stroke, gain = int(np.argmin(np.abs(np.log(amplitudes / r)))), None, 1.0
        mp = skill.periodic[k].mp
        omega = min(mp.omega_rad_s, bounded_omega(mp, r * gain, params, PERIODIC_MARGIN))
        wipes.append(Wipe(s, k, s.centre_m.copy(), r, omega, stroke))
    return Plan(tuple(wipes), params)


_SHAPES: dict[int, tuple] = {}  # id(mp) -> (mp, cycle_shape(mp))


def _cycle_shape_cached(mp) -> tuple[float, float]:
    hit = _SHAPES.get(id(mp))
    if hit is None or hit[0] is not mp:
        if len(_SHAPES) > 256:
            _SHAPES.clear()
        hit = _SHAPES[id(mp)] = (mp, cycle_shape(mp))
    return hit[1]


def wipe_shape(skill: Skill, amplitude_m: float, aspect: float, axis_rad: float, params: PlannerParams
               ) -> tuple[int, np.ndarray | None]:
    """(learned periodic MP, stroke (2, 2) or None) for a stain (or ink) of main-axis amplitude ``amplitude_m``
    [m], width over length ``aspect`` in (0, 1] and main axis ``axis_rad`` [rad].

    The MP minimises ``|log(r_k / r)| + |log(aspect_k / aspect')|`` (size and shape alike count), with
    ``aspect'`` the stroke's aspect (``aspect`` clipped to ``[min_stroke_aspect, 1]``, 1 from ``round_aspect``
    up). A round stain keeps the learned cycle (None); an elongated one gets the cycle turned onto its main axis
    and squeezed across it to ``aspect'`` (an MP round within ``round_aspect`` is not turned, only squeezed, so the
    stroke is symmetric)."""
    want = _stroke_aspect(aspect, params)
    shapes = [_cycle_shape_cached(e.mp) for e in skill.periodic]
    cost = [abs(np.log(e.mp.amplitude_m / amplitude_m)) + abs(np.log(a / want))
            for e, (_, a) in zip(skill.periodic, shapes)]
    k = int(np.argmin(cost))
    return k, _stroke(shapes[k], want, axis_rad, params)


def _stroke_aspect(aspect: float, params: PlannerParams) -> float:
    """The stroke's width over length for a stain (or ink) of ``aspect``: 1 from ``round_aspect`` up."""
    return 1.0 if aspect >= params.round_aspect else max(aspect, params.min_stroke_aspect)


def _stroke(cycle: tuple[float, float], want: float, axis_rad: float, params: PlannerParams) -> np.ndarray | None:
    """The stroke giving a cycle of (main axis, aspect) ``cycle`` the aspect ``want`` along ``axis_rad``; None
    for a round stroke."""
    if want == 1.0:
        return None
    cycle_axis, cycle_aspect = cycle
    if cycle_aspect >= params.round_aspect:
        cycle_axis = axis_rad  # a round cycle: squeeze it along the stain's axes, do not turn it
    across = float(np.clip(want / cycle_aspect, params.min_stroke_aspect, 1.0 / cycle_aspect))
    return stroke_matrix(cycle_axis, axis_rad, across)


#: One adaptation changes r and Omega by at most this factor: while the filters ramp both, r Omega^k passes
#: through values above either end's, by less than the periodic margin leaves for that.
MAX_ADAPT_STEP = 1.5


def adapted_wipe(skill: Skill, planned: Wipe, running: Wipe, ink: Stain, params: PlannerParams) -> Wipe:
    """The wipe's new targets for the ink that remains of its stain (``ink``: centre, size, width, axis).

    Anchor at the ink's centre; r from the ink's size as :func:`plan` sizes a stain, never above the
    ``planned`` r and at least the ``running`` r / :data:`MAX_ADAPT_STEP`; the stroke from the ink's shape;
    Omega within the bounds at the new r and stroke (at most the MP's own and :data:`MAX_ADAPT_STEP` times the
    running Omega). The learned MP stays the one the wipe runs."""
    r_new = float(np.clip(params.amplitude_fraction * ink.size_m, params.min_amplitude_m, params.max_amplitude_m))
    r_new = float(np.clip(r_new, running.amplitude_m / MAX_ADAPT_STEP, planned.amplitude_m))
    wipe = planned
    mp = skill.periodic[wipe.periodic_index].mp
    stroke = _stroke(_cycle_shape_cached(mp), _stroke_aspect(ink.aspect, params), ink.axis_rad, params)
    gain = 1.0 if stroke is None else float(np.linalg.norm(stroke, 2))
    omega = min(mp.omega_rad_s, bounded_omega(mp, r_new * gain, params, PERIODIC_MARGIN),
                MAX_ADAPT_STEP * running.omega_rad_s)
    return Wipe(wipe.stain, wipe.periodic_index, ink.centre_m.copy(), r_new, omega, stroke)


#: A periodic MP is kept this far inside the bounds: a transition ends in its state, and needs some room.
PERIODIC_MARGIN = 0.85
#: Phases sampled on a limit cycle to find its peaks.
_CYCLE_SAMPLES = 720
#: A transition is planned to this share of the bounds: its sampled peaks miss a little between samples.
BOUND_SHARE = 0.97
#: Time step [s] at which a transition's closed form is sampled to find its peaks.
PEAK_DT_S = 0.004


def cycle_peaks(mp, amplitude_m: float, omega_rad_s: float) -> tuple[float, float, float]:
    """Peak speed, acceleration and jerk [m/s, m/s^2, m/s^3] on ``mp``'s limit cycle at that amplitude and
    frequency (closed form; jerk by a central difference of the acceleration in phase)."""
    phases = np.linspace(0.0, 2 * np.pi, _CYCLE_SAMPLES, endpoint=False)
    _, vel, acc = periodic_state(mp, phases, None, amplitude_m, omega_rad_s)
    dphi = phases[1] - phases[0]
    jerk = (np.roll(acc, -1, axis=0) - np.roll(acc, 1, axis=0)) / (2 * dphi) * omega_rad_s
    return (float(np.linalg.norm(vel, axis=1).max()), float(np.linalg.norm(acc, axis=1).max()),
            float(np.linalg.norm(jerk, axis=1).max()))


_UNIT_PEAKS: dict[int, tuple] = {}  # id(mp) -> (mp, its peaks at r = 1 m, Omega = 1 rad/s)


def unit_cycle_peaks(mp) -> tuple[float, float, float]:
    """:func:`cycle_peaks` at amplitude 1 m and Omega 1 rad/s, computed once per MP (the limit cycle scales
    linearly with r: peaks at r are r times these)."""
    hit = _UNIT_PEAKS.get(id(mp))
    if hit is None or hit[0] is not mp:  # the MP itself is kept, so its id is not reused meanwhile
        if len(_UNIT_PEAKS) > 256:
            _UNIT_PEAKS.clear()
        hit = _UNIT_PEAKS[id(mp)] = (mp, cycle_peaks(mp, 1.0, 1.0))
    return hit[1]


def bounded_omega(mp, amplitude_m: float, params: PlannerParams, share: float = 1.0) -> float:
    """The largest Omega [rad/s] at which ``mp``'s limit cycle of amplitude ``amplitude_m`` stays within
    ``share`` of the planner's bounds: speed scales with Omega, acceleration with its square, jerk with its
    cube, each linearly with the amplitude."""
    v1, a1, j1 = (amplitude_m * x for x in unit_cycle_peaks(mp))
    return float(min(share * params.max_speed_m_s / max(v1, 1e-12),
                     np.sqrt(share * params.max_accel_m_s2 / max(a1, 1e-12)),
                     np.cbrt(share * params.max_jerk_m_s3 / max(j1, 1e-12))))


def trajectory_peaks(tp) -> tuple[float, float, float]:
    """Peak speed, acceleration and jerk of a planned transition (``transitional_plan.TransitionPlan``), its
    closed form sampled every :data:`PEAK_DT_S` from start to end (jerk: differences of the acceleration)."""
    n = max(int(np.ceil(tp.duration_s / PEAK_DT_S)), 4)
    smp = evaluate_transition(tp, np.linspace(0.0, tp.duration_s, n + 1))
    jerk = np.diff(smp.acceleration_m_s2, axis=0) / (tp.duration_s / n)
    return (float(np.linalg.norm(smp.velocity_m_s, axis=1).max()),
            float(np.linalg.norm(smp.acceleration_m_s2, axis=1).max()), float(np.linalg.norm(jerk, axis=1).max()))


def bounded_duration(mp, start, goal, duration_s: float, transform: np.ndarray, params: PlannerParams
                     ) -> tuple[float, tuple[float, float, float], bool]:
    """(duration [s], its peaks, whether within the bounds) of a transition lengthened from ``duration_s`` until
    its peaks are within the planner's bounds, at most ``max_transition_stretch`` times.

    Stretching time by k divides the learned part's speed by k, acceleration by k^2, jerk by k^3; the
    boundary states do not scale, so each step re-evaluates (a few closed-form samplings, ~1 ms each).
    """
    T, longest = duration_s, duration_s * params.max_transition_stretch
    best = None
    for _ in range(12):
        peaks = trajectory_peaks(plan_transition_mp(mp, start, goal, T, transform))
        excess = max(peaks[0] / params.max_speed_m_s, np.sqrt(peaks[1] / params.max_accel_m_s2),
                     np.cbrt(peaks[2] / params.max_jerk_m_s3))
        if best is None or excess < best[2]:
            best = (T, peaks, excess)
        if excess <= BOUND_SHARE or T >= longest - 1e-9:
            break
        T = min(longest, T * float(np.clip(excess / BOUND_SHARE, 1.05, 2.0)))
    T, peaks, excess = best
    return T, peaks, bool(excess <= 1.0)


def order_stains(stains: Sequence[Stain], start_m: np.ndarray) -> list[Stain]:
    """Visiting order that shortens the path start -> s1 -> s2 -> ... (open path).

    Up to :data:`EXACT_ORDER_MAX` stains the shortest order of all (every permutation's length at once from the
    distance matrix: 5,040 orders of 7 stains in about 1 ms); more: nearest neighbour, then 2-opt (the segment
    reversal that shortens the path most, from a matrix of every reversal's gain) until none does.
    """
    pts = np.array([s.centre_m for s in stains], dtype=float).reshape(-1, 2)
    n = len(pts)
    if n <= 2:
        d = np.linalg.norm(pts - start_m, axis=1)
        return [stains[i] for i in np.argsort(d, kind="stable")]
    nodes = np.vstack([start_m, pts])  # node 0 is the start
    D = np.linalg.norm(nodes[:, None, :] - nodes[None, :, :], axis=2)
    if n <= EXACT_ORDER_MAX:
        perms = _permutations(n) + 1
        lengths = D[0, perms[:, 0]] + D[perms[:, :-1], perms[:, 1:]].sum(axis=1)
        return [stains[i - 1] for i in perms[int(np.argmin(lengths))]]
    # nearest neighbour from the start (ties to the lower index)
    order, here = [], 0
    left = np.ones(n + 1, dtype=bool)
    left[0] = False
    for _ in range(n):
        nxt = int(np.argmin(np.where(left, D[here], np.inf)))
        order.append(nxt)
        left[nxt] = False
        here = nxt
    return [stains[i - 1] for i in _two_opt(np.array(order), D)]


def _two_opt(order: np.ndarray, D: np.ndarray) -> np.ndarray:
    """2-opt on the open path 0 -> order[0] -> ... (node indices into ``D`` (n+1, n+1)): reverse order[i..j]
    while a reversal shortens it, the best one each time."""
    n = len(order)
    i_idx, j_idx = np.triu_indices(n, 1)
    while True:
        a = np.concatenate([[0], order])  # a[k + 1] is order[k]
        before, first, last = a[i_idx], a[i_idx + 1], a[j_idx + 1]
        gain = D[before, first] - D[before, last]  # edge into the reversed run
        inner = j_idx + 2 < n + 1
        after = a[np.minimum(j_idx + 2, n)]
        gain += np.where(inner, D[last, after] - D[first, after], 0.0)  # edge out of it (none at the path's end)
        k = int(np.argmax(gain))
        if gain[k] <= 1e-12:
            return order
        i, j = i_idx[k], j_idx[k]
        order = np.concatenate([order[:i], order[i:j + 1][::-1], order[j + 1:]])


_PERMS: dict[int, np.ndarray] = {}


def _permutations(n: int) -> np.ndarray:
    """Every permutation of range(n) (n!, n), lexicographic (itertools' order), cached."""
    if n not in _PERMS:
        _PERMS[n] = np.array(list(itertools.permutations(range(n))), dtype=np.intp)
    return _PERMS[n]


def entry_phase(skill: Skill, wipe: Wipe, from_m: np.ndarray, n_candidates: int = 72) -> float:
    """Phase [rad] at which a transition coming from ``from_m`` enters the wipe's periodic MP.

    Among the phases on the re-anchored limit cycle, prefer entry points near
    the incoming tool whose velocity continues the incoming direction, so
    the transition need not turn back: maximise
    ``cos(angle(v(phi), p(phi) - from)) - (|p(phi) - from| - d_min) / r``.
    """
    mp = skill.periodic[wipe.periodic_index].mp
    phases = np.linspace(0.0, 2 * np.pi, n_candidates, endpoint=False)
    pos, vel, _ = periodic_state(mp, phases, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s, wipe.stroke)
    to = pos - from_m
    dist = np.linalg.norm(to, axis=1)
    align = np.einsum("ij,ij->i", vel, to) / np.maximum(np.linalg.norm(vel, axis=1) * dist, 1e-12)
    score = align - (dist - dist.min()) / wipe.amplitude_m
    return float(phases[int(np.argmax(score))])


def exit_phase_delay(skill: Skill, wipe: Wipe, phase_rad: float, towards_m: np.ndarray, n_candidates: int = 72) -> float:
    """Extra phase [rad], in [0, 2 pi), to keep wiping so that the tool leaves towards ``towards_m``.

    Once a stain is clean (kappa = 1) a person finishes the stroke that
    heads for the next stain rather than reversing mid-stroke; leaving with
    the velocity already pointing at the next stain keeps the transition's
    start mismatch small. Among the phases of the coming cycle, pick the
    one maximising ``cos(angle(v(phi), towards - p(phi)))``, preferring the
    earliest of the near-best (within 0.05).

    Parameters
    ----------
    phase_rad : float
        Current phase of the wipe's periodic MP [rad].
    towards_m : array, shape (2,)
        Where the tool goes next (next stain's centre, or the retreat point) [m].
    """
    mp = skill.periodic[wipe.periodic_index].mp
    delays = np.linspace(0.0, 2 * np.pi, n_candidates, endpoint=False)
    pos, vel, _ = periodic_state(mp, phase_rad + delays, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s,
                                 wipe.stroke)
    to = np.asarray(towards_m, dtype=float) - pos
    align = np.einsum("ij,ij->i", vel, to) / np.maximum(np.linalg.norm(vel, axis=1) * np.linalg.norm(to, axis=1), 1e-12)
    return float(delays[int(np.argmax(align >= align.max() - 0.05))])


def plan_transition(
    skill: Skill,
    plan_: Plan,
    wipe: Wipe,
    start: tuple[np.ndarray, np.ndarray, np.ndarray],
    duration_s: float | None = None,
) -> TransitionSpec:
    """The transitional MP from the tool's current state into ``wipe``'s periodic MP.

    Parameters
    ----------
    start : (position, velocity, acceleration), arrays of shape (2,)
        The tool's reference state now [m, m/s, m/s^2].
    duration_s : float, optional
        Use this duration [s] (found earlier by :func:`bounded_duration`
        for a state this one is close to, e.g. on a planner thread) instead
        of searching it now: the search costs a few milliseconds, the rest
        well under one.
    """
    y0, v0, a0 = (np.asarray(x, dtype=float).reshape(2) for x in start)
    phase = entry_phase(skill, wipe, y0)
    mp = skill.periodic[wipe.periodic_index].mp
    goal = periodic_state(mp, phase, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s, wipe.stroke)
    move = goal[0] - y0
    index, transform = _pick_transitional(skill, move)
    duration = transition_duration(skill, index, move, plan_.params)
    goal = tuple(np.asarray(g, float) for g in goal)
    if duration_s is not None:
        if not (np.isfinite(duration_s) and duration_s > 0):
            raise PlanningError(f"duration_s must be a positive number of seconds, got {duration_s!r}")
        return TransitionSpec(index, (y0, v0, a0), goal, float(duration_s), phase, transform, (np.nan,) * 3, True)
    duration, peaks, ok = bounded_duration(skill.transitional[index].mp, (y0, v0, a0), goal, duration, transform,
                                           plan_.params)
    return TransitionSpec(index, (y0, v0, a0), goal, duration, phase, transform, peaks, ok)


def transition_duration(skill: Skill, index: int, move_m: np.ndarray, params: PlannerParams) -> float:
    """Duration T [s] of a transition that plays learned transition ``index`` over ``move_m``.

    Mapping a demonstration of duration ``T_d`` and displacement ``d`` onto a
    move of length ``s |d|`` in time ``T`` multiplies its accelerations by
    ``s (T_d / T)^2`` (docs/transitional_mp.md, section 2). By default ``T``
    keeps that factor at 1, ``T = T_d sqrt(s)``, so the transition is as
    brisk as the human's, no more; a fixed ``transition_speed_m_s`` gives
    ``T = |move| / speed`` instead. Never shorter than ``min_transition_s``,
    never faster on average than ``max_transition_speed_m_s``.
    """
    dist = float(np.linalg.norm(move_m))
    floor = max(params.min_transition_s, dist / params.max_transition_speed_m_s)
    if params.transition_speed_m_s is not None:
        return max(floor, dist / params.transition_speed_m_s)
    mp = skill.transitional[index].mp
    d_demo = float(np.linalg.norm(mp.demo_displacement_m))
    if d_demo <= MIN_DEMO_DISPLACEMENT_M or dist < 1e-3:
        return max(floor, dist / demonstrated_transition_speed(skill))
    return max(floor, mp.demo_duration_s * float(np.sqrt(dist / d_demo)))


def demonstrated_transition_speed(skill: Skill) -> float:
    """Median mean speed [m/s] of the demonstrated transitions between stains (0.3 m/s if none)."""
    speeds = [
        np.linalg.norm(e.mp.demo_displacement_m) / e.mp.demo_duration_s
        for e in skill.transitional
        if np.linalg.norm(e.mp.demo_displacement_m) > MIN_DEMO_DISPLACEMENT_M
    ]
    return float(np.clip(np.median(speeds), 0.1, 0.8)) if speeds else 0.3


def _pick_transitional(skill: Skill, move_m: np.ndarray) -> tuple[int, np.ndarray]:
    """Learned transition most alike ``move_m`` and the similarity mapping its forcing onto it.

    Candidates are the transitions demonstrated *between* two periodic MPs
    (the approach from rest and the final retreat have another shape), or
    all of them if there are none. Alike = closest demonstrated displacement
    length (log ratio). The map is ``s R`` with R the rotation taking the
    demonstrated displacement direction onto the new one and s the length
    ratio. When no demonstrated transition has a usable direction (all
    shorter than :data:`MIN_DEMO_DISPLACEMENT_M`) or the move is tiny, the
    forcing is switched off (a zero map): the transition is then the pure
    third-order target-crossing system. A skill with no transitional MP at
    all cannot be planned (PlanningError).
    """
    if not skill.transitional:
        raise PlanningError("the skill has no transitional MP to build a transition from")
    dist = float(np.linalg.norm(move_m))
    usable = [(i, e) for i, e in enumerate(skill.transitional)
              if np.linalg.norm(e.mp.demo_displacement_m) > MIN_DEMO_DISPLACEMENT_M]
    periodic_segments = {e.segment for e in skill.periodic}
    between = [(i, e) for i, e in usable if {e.segment - 1, e.segment + 1} <= periodic_segments]
    cands = between or usable
    if not cands or dist < 1e-3:
        return 0, np.zeros((2, 2))
    i, e = min(cands, key=lambda ie: abs(np.log(np.linalg.norm(ie[1].mp.demo_displacement_m) / dist)))
    return i, similarity_transform(e.mp.demo_displacement_m, move_m)
