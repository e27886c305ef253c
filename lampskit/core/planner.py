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
from lampskit.core.periodic import periodic_state
from lampskit.core.skill import Skill
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
        Extent of the stain [m] (its larger side).
    """

    id: int
    centre_m: np.ndarray
    size_m: float

    def __post_init__(self) -> None:
        c = np.asarray(self.centre_m, dtype=float).reshape(-1)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise PlanningError(f"stain {self.id}: centre_m must be 2 finite numbers, got {self.centre_m!r}")
        if not (np.isfinite(self.size_m) and self.size_m > 0):
            raise PlanningError(f"stain {self.id}: size_m must be a positive number, got {self.size_m!r}")
        object.__setattr__(self, "centre_m", c)


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
    """

    amplitude_fraction: float = 0.5
    min_amplitude_m: float = 0.01
    max_amplitude_m: float = 0.15
    transition_speed_m_s: float | None = None
    min_transition_s: float = 0.6
    max_transition_speed_m_s: float = 0.8
    order: str = "shortest"

    def __post_init__(self) -> None:
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
    """One periodic MP of the plan: which learned MP, where and how big."""

    stain: Stain
    periodic_index: int
    anchor_m: np.ndarray
    amplitude_m: float
    omega_rad_s: float


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
        k = int(np.argmin(np.abs(np.log(amplitudes / r))))
        wipes.append(Wipe(s, k, s.centre_m.copy(), r, skill.periodic[k].mp.omega_rad_s))
    return Plan(tuple(wipes), params)


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
    pos, vel, _ = periodic_state(mp, phases, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s)
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
    pos, vel, _ = periodic_state(mp, phase_rad + delays, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s)
    to = np.asarray(towards_m, dtype=float) - pos
    align = np.einsum("ij,ij->i", vel, to) / np.maximum(np.linalg.norm(vel, axis=1) * np.linalg.norm(to, axis=1), 1e-12)
    return float(delays[int(np.argmax(align >= align.max() - 0.05))])


def plan_transition(
    skill: Skill,
    plan_: Plan,
    wipe: Wipe,
    start: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> TransitionSpec:
    """The transitional MP from the tool's current state into ``wipe``'s periodic MP.

    Parameters
    ----------
    start : (position, velocity, acceleration), arrays of shape (2,)
        The tool's reference state now [m, m/s, m/s^2].
    """
    y0, v0, a0 = (np.asarray(x, dtype=float).reshape(2) for x in start)
    phase = entry_phase(skill, wipe, y0)
    mp = skill.periodic[wipe.periodic_index].mp
    goal = periodic_state(mp, phase, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s)
    move = goal[0] - y0
    index, transform = _pick_transitional(skill, move)
    duration = transition_duration(skill, index, move, plan_.params)
    return TransitionSpec(index, (y0, v0, a0), tuple(np.asarray(g, float) for g in goal), duration, phase, transform)


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
