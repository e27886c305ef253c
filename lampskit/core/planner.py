"""Run-time generalisation (paper section II-C): chain the learned MPs across a new board.

Given a skill, the stains a perception reports (centre and size in the
board plane) and the tool's current state, the planner

1. orders the stains to shorten the travel (exact for up to
   :data:`~lampskit.core.stain_order.EXACT_ORDER_MAX` stains, nearest neighbour + 2-opt above),
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
   (:func:`~lampskit.core.kinematic_bounds.bounded_omega`), and a transition is lengthened until its
   closed-form trajectory does (:func:`~lampskit.core.kinematic_bounds.bounded_duration`). Position,
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

from collections.abc import Sequence

import numpy as np

from lampskit.core.kinematic_bounds import PERIODIC_MARGIN, bounded_duration, bounded_omega
from lampskit.core.periodic import cycle_shape, periodic_state, stroke_matrix
from lampskit.core.planner_types import Plan, PlannerParams, Stain, TransitionSpec, Wipe
from lampskit.core.skill import Skill
from lampskit.core.stain_order import order_stains
from lampskit.core.transitional_plan import similarity_transform
from lampskit.errors import PlanningError

#: Demonstrated transitions shorter than this [m] carry no usable direction.
MIN_DEMO_DISPLACEMENT_M = 0.02


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


def exit_phase_delay(skill: Skill, wipe: Wipe, phase_rad: float, towards_m: np.ndarray,
                     n_candidates: int = 72) -> float:
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
        Use this duration [s] (found earlier by :func:`~lampskit.core.kinematic_bounds.bounded_duration`
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
    goal = (np.asarray(goal[0], float), np.asarray(goal[1], float), np.asarray(goal[2], float))
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
