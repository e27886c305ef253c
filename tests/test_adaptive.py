"""Adaptive wiping: strokes shaped to the stain, the MP picked by shape and size, the periodic MP following the ink
that remains while it wipes, and perception reporting that ink."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import msgspec
import numpy as np
import pytest

from interfaces.messages import StainObservation
from interfaces.stain_shape import shape_of
from lampskit.core.chain import ChainResult, ChainStep, MpChain
from lampskit.core.kinematic_bounds import cycle_peaks
from lampskit.core.periodic import check_stroke, cycle_shape, periodic_state, stroke_matrix
from lampskit.core.periodic_runner import PeriodicRunner, PeriodicStatus
from lampskit.core.planner import MAX_ADAPT_STEP, adapted_wipe, plan, wipe_shape
from lampskit.core.planner_types import PlannerParams, Stain
from lampskit.core.skill import PeriodicEntry, Skill
from lampskit.errors import PlanningError
from lampskit.learn.learn import learn_skill
from lampskit.learn.periodic_fit import learn_periodic
from lampskit.learn.synth import synthesize_demo

ADAPTIVE = PlannerParams(adaptive=True)


@pytest.fixture(scope="module")
def skill() -> Skill:
    return learn_skill(synthesize_demo(4, seed=0).demo)[0]


def _main_axis_and_aspect(points: np.ndarray) -> tuple[float, float]:
    """Direction [rad] in (-pi/2, pi/2] and across/along extent ratio of a closed curve's points (n, 2)."""
    p = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov(p.T))
    axis = math.atan2(vecs[1, -1], vecs[0, -1])
    axis = axis + math.pi if axis <= -math.pi / 2 else axis - math.pi if axis > math.pi / 2 else axis
    return axis, float(np.ptp(p @ vecs[:, 0]) / np.ptp(p @ vecs[:, -1]))


def _angle_diff(a: float, b: float) -> float:
    """Difference of two axis directions (modulo pi) [rad], in [0, pi/2]."""
    d = (a - b) % math.pi
    return min(d, math.pi - d)


# ---------------------------------------------------------------------------------------------- the stroke
def test_stroke_matrix_turns_the_main_axis_and_squeezes_across_it():
    S = stroke_matrix(0.0, 0.6, 0.4)
    main, across = np.array([math.cos(0.6), math.sin(0.6)]), np.array([-math.sin(0.6), math.cos(0.6)])
    np.testing.assert_allclose(S @ [1.0, 0.0], main, atol=1e-12)
    np.testing.assert_allclose(S @ [0.0, 1.0], 0.4 * across, atol=1e-12)
    sym = stroke_matrix(0.6, 0.6, 0.4)  # a round cycle is squeezed along the stain's axes, not turned
    np.testing.assert_allclose(sym, sym.T, atol=1e-12)
    np.testing.assert_allclose(np.linalg.eigvalsh(sym), [0.4, 1.0], atol=1e-12)
    np.testing.assert_allclose(stroke_matrix(0.3, 0.3, 1.0), np.eye(2), atol=1e-12)


@pytest.mark.parametrize("bad, match", [(np.eye(3), "finite \\(2, 2\\)"), (np.full((2, 2), np.nan), "finite"),
                                        (5 * np.eye(2), "stretch"), (np.zeros((2, 2)), "stretch")])
def test_a_bad_stroke_is_refused_naming_the_problem(bad, match):
    with pytest.raises(PlanningError, match=match):
        check_stroke(bad, 2)


def test_the_runner_with_a_stroke_follows_the_stroked_limit_cycle(skill):
    mp = skill.periodic[0].mp
    S, anchor, r, om = stroke_matrix(0.2, 1.0, 0.5), np.array([0.3, 0.2]), 0.04, mp.omega_rad_s
    run = PeriodicRunner(mp, anchor, r, om, 1.0, stroke=S)
    for _ in range(2000):
        run.update(0.001)
    p, v, a = periodic_state(mp, run.phase_rad, anchor, r, om, stroke=S)
    assert np.abs(run.position_m - p).max() < 1e-5 and np.abs(run.velocity_m_s - v).max() < 1e-4
    assert np.abs(run.acceleration_m_s2 - a).max() < 1e-2 * np.abs(a).max()
    # the cycle's shape is the stroke's: main axis 1.0 rad, across / along = 0.5 x the learned cycle's aspect
    phases = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    axis, aspect = _main_axis_and_aspect(periodic_state(mp, phases, anchor, r, om, stroke=S)[0])
    assert _angle_diff(axis, 1.0) < 0.05 and aspect == pytest.approx(0.5 * cycle_shape(mp)[1], rel=0.1)


def test_an_identity_stroke_changes_nothing_and_a_bad_target_is_refused(skill):
    mp = skill.periodic[0].mp
    plain, with_eye = PeriodicRunner(mp, start_phase_rad=0.5), PeriodicRunner(mp, start_phase_rad=0.5)
    assert with_eye.set_targets(stroke=np.eye(2)) == PeriodicStatus.WORKING
    for _ in range(500):
        plain.update(0.001), with_eye.update(0.001)
    np.testing.assert_allclose(with_eye.acceleration_m_s2, plain.acceleration_m_s2, rtol=0, atol=1e-12)
    assert with_eye.set_targets(stroke=np.eye(3)) == PeriodicStatus.ERROR_INVALID_INPUT
    assert with_eye.set_targets(stroke=[[np.inf, 0], [0, 1]]) == PeriodicStatus.ERROR_INVALID_INPUT
    np.testing.assert_array_equal(with_eye.stroke, np.eye(2))


def test_adapting_while_wiping_keeps_the_reference_continuous_and_inside_the_bounds(skill):
    """Anchor 1 cm, r to 2/3, the stroke squeezed and turned, Omega up as the bounds allow: all at once."""
    mp, params = skill.periodic[0].mp, ADAPTIVE
    run = PeriodicRunner(mp, np.array([0.3, 0.2]), 0.05, 6.0, 0.0)
    acc, dt = [], 0.001
    for k in range(4000):
        if k == 1000:
            assert run.set_targets(anchor_m=np.array([0.31, 0.2]), amplitude_m=0.05 / MAX_ADAPT_STEP,
                                   omega_rad_s=6.0 * MAX_ADAPT_STEP, stroke=stroke_matrix(0.0, 0.7, 0.5)) == 0
        run.update(dt)
        acc.append(run.acceleration_m_s2.copy())
    acc = np.array(acc)
    steps = np.linalg.norm(np.diff(acc, axis=0), axis=1)
    # no step in acceleration at the re-target (a step would be one tick tens of times the others): the ticks
    # right after it change it by at most twice as much as the ticks before (the jerk rises through the ramps)
    assert steps[999:1002].max() < 2.0 * steps[990:999].max()
    assert steps.max() / dt < params.max_jerk_m_s3  # and the jerk it ramps to stays inside the bounds
    assert not run.is_ramping or np.linalg.norm(run.stroke - stroke_matrix(0.0, 0.7, 0.5)) < 1e-3


# ---------------------------------------------------------------------------------------------- planning
def _ellipse_mp(aspect: float, amplitude_m: float):
    """A periodic MP learned from an elliptic wipe (main axis along board x)."""
    t = np.arange(0.0, 6.0, 0.01)
    om = 2 * np.pi * 1.2
    y = np.column_stack([amplitude_m * np.cos(om * t), aspect * amplitude_m * np.sin(om * t)]) + [0.4, 0.3]
    return learn_periodic(t, y)


def test_the_mp_is_picked_by_shape_as_well_as_size(skill):
    round_mp, flat_mp = skill.periodic[0].mp, _ellipse_mp(0.35, skill.periodic[0].mp.amplitude_m)
    assert cycle_shape(flat_mp)[1] == pytest.approx(0.35, abs=0.08)
    two = dataclasses.replace(skill, periodic=(skill.periodic[0], PeriodicEntry(1, 1, 4.0, flat_mp)))
    r = round_mp.amplitude_m
    assert wipe_shape(two, r, 1.0, 0.0, ADAPTIVE) == (0, None)  # round stain: the round MP, not stretched
    k, S = wipe_shape(two, r, 0.35, 1.2, ADAPTIVE)
    assert k == 1  # elongated stain of the same size: the flat MP, turned onto the stain
    axis, aspect = _main_axis_and_aspect(periodic_state(flat_mp, np.linspace(0, 6.28, 360), np.zeros(2), r, 1.0,
                                                        stroke=S)[0])
    assert _angle_diff(axis, 1.2) < 0.08 and aspect == pytest.approx(0.35, abs=0.08)


def test_an_adaptive_plan_strokes_elongated_stains_and_stays_inside_the_bounds(skill):
    stains = [Stain(0, np.array([0.3, 0.3]), 0.16, 0.05, 0.5), Stain(1, np.array([0.7, 0.4]), 0.08, 0.075, 0.0)]
    fixed = plan(skill, stains, np.zeros(2), PlannerParams(adaptive=False))
    shaped = plan(skill, stains, np.zeros(2), ADAPTIVE)
    assert all(w.stroke is None for w in fixed.wipes)
    by_id = {w.stain.id: w for w in shaped.wipes}
    assert by_id[1].stroke is None  # near round: the learned cycle
    long = by_id[0]
    axis, aspect = _main_axis_and_aspect(periodic_state(skill.periodic[long.periodic_index].mp,
                                                        np.linspace(0, 6.28, 360), long.anchor_m, long.amplitude_m,
                                                        long.omega_rad_s, long.stroke)[0])
    assert _angle_diff(axis, 0.5) < 0.1 and aspect < 0.5
    for w in shaped.wipes:
        mp = skill.periodic[w.periodic_index].mp
        v, a, j = (w.stroke_gain * x for x in cycle_peaks(mp, w.amplitude_m, w.omega_rad_s))
        assert v <= ADAPTIVE.max_speed_m_s and a <= ADAPTIVE.max_accel_m_s2 and j <= ADAPTIVE.max_jerk_m_s3


def test_adapted_targets_follow_the_ink_within_their_limits(skill):
    planned = plan(skill, [Stain(0, np.array([0.4, 0.3]), 0.12)], np.zeros(2), ADAPTIVE).wipes[0]
    ink = Stain(0, np.array([0.43, 0.31]), 0.03, 0.01, 0.9)  # a third of it left, a streak on one side
    once = adapted_wipe(skill, planned, planned, ink, ADAPTIVE)
    np.testing.assert_allclose(once.anchor_m, ink.centre_m)
    assert once.amplitude_m == pytest.approx(planned.amplitude_m / MAX_ADAPT_STEP)  # at most 1.5x smaller at once
    assert planned.omega_rad_s <= once.omega_rad_s <= MAX_ADAPT_STEP * planned.omega_rad_s
    assert once.stroke is not None and _angle_diff(_main_axis_and_aspect(
        periodic_state(skill.periodic[0].mp, np.linspace(0, 6.28, 360), np.zeros(2), 1.0, 1.0,
                       stroke=once.stroke)[0])[0], 0.9) < 0.1
    twice = adapted_wipe(skill, planned, once, ink, ADAPTIVE)
    assert twice.amplitude_m < once.amplitude_m
    grown = adapted_wipe(skill, planned, twice, Stain(0, ink.centre_m, 0.5), ADAPTIVE)
    assert grown.amplitude_m == planned.amplitude_m  # never above the plan's r


class _Book:
    """A stain book for the chain: one stain, its ink as perception would report it."""

    max_passes = 3

    def __init__(self, stain: Stain) -> None:
        self.stains = {stain.id: stain}
        self._stain = stain

    def is_done(self, stain_id: int) -> bool:
        return False

    def end_pass(self, stain_id: int, clock_s: float) -> bool:
        return False

    def open_stains(self, clock_s: float, by_ink: bool = False, exclude: int | None = None) -> list[Stain]:
        return [self._stain] if self._stain.id != exclude else []


class _Ref:
    def __init__(self) -> None:
        self.xy, self.v_xy, self.a_xy = np.array([0.3, 0.25]), np.zeros(2), np.zeros(2)


def _wiping_chain(skill, params: PlannerParams):
    stain = Stain(0, np.array([0.4, 0.3]), 0.1)
    chain, counters = MpChain(skill, params, 100.0, Counter()), None
    book, ref = _Book(stain), _Ref()
    assert chain.start(plan(skill, [stain], ref.xy, params), ref) == ChainResult.TRANSITION
    clock = 0.0
    while chain.step != ChainStep.WIPE:
        assert chain.update(0.001, ref, book, clock) >= 0
        clock += 0.001
    return chain, book, ref, clock, counters


def test_the_chain_follows_the_ink_while_wiping_at_most_every_half_second(skill):
    chain, book, ref, clock, _ = _wiping_chain(skill, ADAPTIVE)
    r0 = chain.wipe.amplitude_m
    book.stains[0] = dataclasses.replace(book.stains[0], ink=Stain(0, np.array([0.42, 0.3]), 0.05))
    assert chain.adapt(book, clock) == ChainResult.WORKING
    assert chain.counters["adaptations"] == 1 and chain.wipe.amplitude_m < r0
    assert chain.adapt(book, clock + 0.1) is None  # too soon
    for _ in range(3000):
        assert chain.update(0.001, ref, book, clock) == ChainResult.WORKING
        clock += 0.001
    runner = chain._runner
    np.testing.assert_allclose(runner.anchor_m, [0.42, 0.3], atol=1e-4)
    assert runner.amplitude_m == pytest.approx(chain.wipe.amplitude_m, rel=1e-3)
    for _ in range(5):  # r goes on shrinking towards the ink's size, 1.5x at most per re-target
        if chain.adapt(book, clock) is None:
            break
        for _ in range(600):
            chain.update(0.001, ref, book, clock)
            clock += 0.001
    assert chain.wipe.amplitude_m == pytest.approx(ADAPTIVE.amplitude_fraction * 0.05)
    assert chain.adapt(book, clock + 1.0) is None  # the same ink, reached: nothing to change


def test_fixed_wiping_only_follows_a_moved_stain(skill):
    chain, book, ref, clock, _ = _wiping_chain(skill, PlannerParams(adaptive=False))
    book.stains[0] = dataclasses.replace(book.stains[0], ink=Stain(0, np.array([0.42, 0.3]), 0.05))
    assert chain.adapt(book, clock) is None  # the ink is not followed
    book.stains[0] = dataclasses.replace(book.stains[0], centre_m=np.array([0.405, 0.3]))
    assert chain.adapt(book, clock) == ChainResult.WORKING
    assert chain.counters["adaptations"] == 0


# ---------------------------------------------------------------------------------------------- perception
def test_shape_reports_the_main_axis_and_the_width():
    res = 0.002
    xs, ys = np.meshgrid(np.arange(-0.05, 0.05, res), np.arange(-0.01, 0.01, res))
    pts = np.column_stack([xs.ravel(), ys.ravel()])
    turn = np.array([[math.cos(0.5), -math.sin(0.5)], [math.sin(0.5), math.cos(0.5)]])
    s = shape_of(pts @ turn.T + [0.3, 0.2], res)
    assert s.axis_rad == pytest.approx(0.5, abs=0.02)
    assert s.size_m == pytest.approx(0.1, abs=0.004) and s.width_m == pytest.approx(0.02, abs=0.004)
    one = shape_of(np.array([[0.1, 0.1]]), res)
    assert one.width_m == one.size_m == pytest.approx(res)


def test_perception_tracks_the_ink_that_remains_and_keeps_hidden_ink_as_last_seen():
    from perception.classify import InkMap
    from perception.params import KappaParams, StainParams
    from perception.rectify import BoardGrid
    from perception.tracking import StainTracker

    grid = BoardGrid((0.4, 0.3), 0.002)
    tracker = StainTracker(grid, StainParams(confirm_s=0.0), KappaParams(), ink_level=0.3)
    rows, cols = grid.shape
    looked = np.ones((rows, cols), bool)
    d = np.zeros((rows, cols), np.float32)
    d[70:80, 50:110] = 1.0  # a 12 cm x 2 cm streak along board x, cols 50-109

    def frame(d, hidden=None):
        occ = np.zeros_like(looked) if hidden is None else hidden
        vis = looked & ~occ
        return InkMap(np.where(vis, d, 0.0).astype(np.float32), occ, vis & (d >= 0.3), looked)

    for t in (0.0, 0.1):
        tracker.update(frame(d), t)
    (tr,) = tracker.tracks
    assert tr.ink.size_m == pytest.approx(0.12, abs=0.006) and _angle_diff(tr.ink.axis_rad, 0.0) < 0.05
    d[:, 50:80] = 0.0  # the left half wiped
    tracker.update(frame(d), 0.15)
    assert tr.ink.size_m == pytest.approx(0.12, abs=0.006)  # refreshed every INK_EVERY_S, not every frame
    tracker.update(frame(d), 0.3)
    assert tr.ink.size_m == pytest.approx(0.06, abs=0.006)
    assert tr.ink.centre_m[0] == pytest.approx(grid.xy_of(np.array([75]), np.array([95]))[0, 0], abs=0.003)
    assert tr.shape.size_m == pytest.approx(0.12, abs=0.006)  # the stain itself is as first seen
    hidden = np.zeros_like(looked)
    hidden[:, 90:] = True  # the eraser over the right half: its ink stays as last seen
    d[:, 80:] = 0.0
    tracker.update(frame(d, hidden), 0.6)
    assert tr.ink is not None and tr.ink.size_m == pytest.approx(0.04, abs=0.006)
    tracker.update(frame(d), 0.9)  # seen again, clean: no ink left
    assert tr.ink is None


def test_stain_observations_carry_the_ink_and_older_ones_still_decode():
    obs = StainObservation(id=1, centre_board_m=[0.2, 0.1], centre_world_m=[0.5, 0.0, 0.3], size_m=0.08,
                           extent_board_m=[0.08, 0.03], remaining=0.5, visible=1.0, kappa=False, width_m=0.03,
                           axis_board_rad=0.2, ink_centre_board_m=[0.21, 0.1], ink_size_m=0.04, ink_width_m=0.02,
                           ink_axis_board_rad=0.1)
    assert msgspec.json.decode(msgspec.json.encode(obs), type=StainObservation) == obs
    old = msgspec.json.encode([1, [0.2, 0.1], [0.5, 0.0, 0.3], 0.08, [0.08, 0.03], 0.5, 1.0, False])
    back = msgspec.json.decode(old, type=StainObservation)
    assert back.ink_centre_board_m == [] and back.width_m == 0.0
    with pytest.raises(ValueError, match="ink_size_m must be positive"):
        StainObservation(id=1, centre_board_m=[0.2, 0.1], centre_world_m=[0.5, 0.0, 0.3], size_m=0.08,
                         extent_board_m=[0.08, 0.03], remaining=0.5, visible=1.0, kappa=False,
                         ink_centre_board_m=[0.2, 0.1])
