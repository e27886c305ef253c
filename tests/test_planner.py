"""Planner (paper section II-C): stain order, re-anchoring, entry/exit phases, 1 kHz rollout."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lampskit.core.periodic import periodic_state
from lampskit.core.planner import entry_phase, exit_phase_delay, plan
from lampskit.core.planner_types import Plan, PlannerParams, Stain
from lampskit.core.rollout import junction_step_ratios, rollout
from lampskit.core.stain_order import order_stains
from lampskit.errors import PlanningError
from lampskit.learn.learn import learn_skill
from lampskit.learn.synth import synthesize_demo


@pytest.fixture(scope="module")
def skill():
    return learn_skill(synthesize_demo(4, seed=0).demo)[0]


def _board(seed: int, n: int = 3) -> list[Stain]:
    rng = np.random.default_rng(seed)
    return [Stain(i, rng.uniform([0.15, 0.15], [0.95, 0.65]), float(rng.uniform(0.04, 0.1))) for i in range(n)]


def _path_length(start, stains) -> float:
    pts = np.vstack([start, [s.centre_m for s in stains]])
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


@pytest.mark.parametrize("n", [1, 2, 4, 6])
def test_order_is_the_shortest_open_path(n):
    rng = np.random.default_rng(n)
    stains = [Stain(i, rng.uniform(0, 1, 2), 0.05) for i in range(n)]
    start = np.zeros(2)
    best = min(_path_length(start, [stains[i] for i in p]) for p in itertools.permutations(range(n)))
    assert _path_length(start, order_stains(stains, start)) == pytest.approx(best)


def test_large_boards_use_two_opt_and_beat_nearest_neighbour_or_tie():
    rng = np.random.default_rng(7)
    stains = [Stain(i, rng.uniform(0, 1, 2), 0.05) for i in range(12)]
    start = np.zeros(2)
    ordered = order_stains(stains, start)
    assert sorted(s.id for s in ordered) == list(range(12))
    # nearest neighbour, by hand
    left, here, nn = list(stains), start, []
    while left:
        k = int(np.argmin([np.linalg.norm(s.centre_m - here) for s in left]))
        here = left[k].centre_m
        nn.append(left.pop(k))
    assert _path_length(start, ordered) <= _path_length(start, nn) + 1e-12


def test_each_wipe_is_reanchored_and_scaled_to_its_stain(skill):
    stains = _board(3) + [Stain(9, np.array([0.5, 0.5]), 1.0)]  # a huge stain: amplitude clamped
    params = PlannerParams(order="given")
    pl = plan(skill, stains, np.zeros(2), params)
    assert pl.order == (0, 1, 2, 9)
    for w in pl.wipes:
        assert np.array_equal(w.anchor_m, w.stain.centre_m)
        expected = np.clip(params.amplitude_fraction * w.stain.size_m, params.min_amplitude_m, params.max_amplitude_m)
        assert w.amplitude_m == pytest.approx(expected)
        assert 0 <= w.periodic_index < len(skill.periodic)
    assert pl.wipes[-1].amplitude_m == params.max_amplitude_m


def test_entry_phase_continues_the_approach_direction(skill):
    wipe = plan(skill, [Stain(0, np.array([0.5, 0.5]), 0.08)], np.zeros(2)).wipes[0]
    mp = skill.periodic[wipe.periodic_index].mp
    for approach in ([0.0, 0.0], [1.0, 1.0], [0.5, 0.0], [0.0, 0.5]):
        phi = entry_phase(skill, wipe, np.array(approach))
        pos, vel, _ = periodic_state(mp, phi, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s)
        to = pos - np.array(approach)
        assert vel @ to / (np.linalg.norm(vel) * np.linalg.norm(to)) > 0.5


def test_exit_phase_leaves_towards_the_next_stain(skill):
    wipe = plan(skill, [Stain(0, np.array([0.5, 0.5]), 0.08)], np.zeros(2)).wipes[0]
    mp = skill.periodic[wipe.periodic_index].mp
    for towards in ([1.0, 0.5], [0.0, 0.5], [0.5, 1.0]):
        delay = exit_phase_delay(skill, wipe, 0.3, np.array(towards))
        assert 0.0 <= delay < 2 * np.pi
        pos, vel, _ = periodic_state(mp, 0.3 + delay, wipe.anchor_m, wipe.amplitude_m, wipe.omega_rad_s)
        to = np.array(towards) - pos
        assert vel @ to / (np.linalg.norm(vel) * np.linalg.norm(to)) > 0.5


@pytest.mark.parametrize("seed", [1000, 1001, 1002])
def test_rollout_visits_every_stain_and_is_continuous_at_every_junction(skill, seed):
    stains = _board(seed)
    start = np.array([0.05, 0.05])
    pl = plan(skill, stains, start)
    ro = rollout(skill, pl, (start, np.zeros(2), np.zeros(2)), cycles_per_stain=2)
    assert np.allclose(np.diff(ro.t_s), 0.001)
    assert np.allclose(ro.position_m[0], start, atol=1e-3)
    # wiping happens at each stain, in plan order, within reach of its centre
    per = ro.kind == "periodic"
    visited = [k for k, _ in itertools.groupby(ro.stain[per])]
    assert tuple(visited) == pl.order
    for w in pl.wipes:
        pts = ro.position_m[per & (ro.stain == w.stain.id)]
        assert np.linalg.norm(pts.mean(axis=0) - w.stain.centre_m) < 0.5 * w.amplitude_m
        assert np.linalg.norm(pts - w.stain.centre_m, axis=1).max() < 2.5 * w.amplitude_m
    # 2 junctions per stain but the first (the initial transition starts the rollout)
    assert len(ro.junctions) == 2 * len(stains) - 1
    ratios = junction_step_ratios(ro)
    assert ratios.max() < 1.6, ratios  # no junction steps more than the ticks around it
    # and the transitions stay as brisk as the wiping, not more
    acc = np.linalg.norm(ro.acceleration_m_s2, axis=1)
    assert acc[~per].max() < 2.5 * acc[per].max()


def test_rollout_starts_at_the_start_state_at_t0(skill):
    start = (np.array([0.05, 0.05]), np.array([0.1, 0.0]), np.array([0.0, 0.5]))
    ro = rollout(skill, plan(skill, _board(3), start[0]), start, cycles_per_stain=1)
    assert ro.t_s[0] == 0.0
    assert np.array_equal(ro.position_m[0], start[0]) and np.array_equal(ro.velocity_m_s[0], start[1])
    assert np.array_equal(ro.acceleration_m_s2[0], start[2])


def test_far_stains_get_longer_not_faster_transitions(skill):
    far = [Stain(0, np.array([3.0, 0.0]), 0.05)]
    params = PlannerParams(max_transition_speed_m_s=0.5)
    pl = plan(skill, far, np.zeros(2), params)
    ro = rollout(skill, pl, (np.zeros(2),) * 3, cycles_per_stain=1)
    spec = ro.transitions[0]
    assert np.linalg.norm(spec.goal[0] - spec.start[0]) / spec.duration_s <= 0.5 + 1e-9


def test_junction_ratio_detects_a_real_jump(skill):
    pl = plan(skill, _board(1000), np.array([0.05, 0.05]))
    ro = rollout(skill, pl, (np.array([0.05, 0.05]), np.zeros(2), np.zeros(2)), cycles_per_stain=2)
    j = ro.junctions[1]
    ro.acceleration_m_s2[j:] += 0.5  # an acceleration step of 0.7 m/s^2
    assert junction_step_ratios(ro)[1, 2] > 3.0


def test_custom_completion_stops_each_wipe(skill):
    pl = plan(skill, _board(5), np.zeros(2))
    seen = []

    def done(wipe, cycles):
        seen.append(wipe.stain.id)
        return cycles >= 1.0

    ro = rollout(skill, pl, (np.zeros(2), np.zeros(2), np.zeros(2)), is_done=done)
    assert set(seen) == {0, 1, 2}
    for k, w in enumerate(pl.wipes):
        n = np.count_nonzero((ro.kind == "periodic") & (ro.stain == w.stain.id))
        period = 2 * np.pi / w.omega_rad_s
        # one cycle, plus at most one more to leave towards the next stain (none after the last)
        longest = 1.01 if k == len(pl.wipes) - 1 else 2.05
        assert 1.0 * period - 0.0011 <= n * 0.001 <= longest * period  # the tick that ends the chain is no sample


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda sk: plan(sk, [], np.zeros(2)), "no stains"),
        (lambda sk: plan(sk, [Stain(1, np.zeros(2), 0.1), Stain(1, np.ones(2), 0.1)], np.zeros(2)), "unique"),
        (lambda sk: plan(sk, [Stain(1, np.zeros(2), 0.1)], np.array([np.nan, 0.0])), "start_position_m"),
        (lambda sk: Stain(1, np.zeros(3), 0.1), "centre_m"),
        (lambda sk: Stain(1, np.zeros(2), 0.0), "size_m"),
        (lambda sk: PlannerParams(order="random"), "order"),
        (lambda sk: rollout(sk, plan(sk, [Stain(1, np.ones(2), 0.1)], np.zeros(2)),
                            (np.zeros(2),) * 3, dt_s=0.5), "dt_s"),
        *[(lambda sk, c=c: rollout(sk, plan(sk, [Stain(1, np.ones(2), 0.1)], np.zeros(2)),
                                   (np.zeros(2),) * 3, cycles_per_stain=c), "cycles_per_stain")
          for c in (float("nan"), float("inf"), 0.0, -1.0)],
        (lambda sk: PlannerParams(max_transition_speed_m_s=50.0), "max_transition_speed_m_s"),
    ],
)
def test_bad_planner_input_names_the_problem(skill, call, match):
    with pytest.raises(PlanningError, match=match):
        call(skill)


def _length_of(order, start) -> float:
    p = np.vstack([start] + [s.centre_m for s in order])
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


@pytest.mark.parametrize("n", [3, 5, 6, 7])
def test_up_to_seven_stains_the_order_is_the_shortest_of_all(n):
    import itertools

    from lampskit.core.planner_types import Stain
    from lampskit.core.stain_order import order_stains

    rng = np.random.default_rng(n)
    for _ in range(5):
        stains = [Stain(i, rng.uniform(0, 1, 2), 0.05) for i in range(n)]
        start = rng.uniform(0, 1, 2)
        best = min(_length_of([stains[i] for i in p], start) for p in itertools.permutations(range(n)))
        assert _length_of(order_stains(stains, start), start) == pytest.approx(best, abs=1e-12)


@pytest.mark.parametrize("n", [8, 30, 100])
def test_more_stains_get_a_two_opt_local_optimum_no_longer_than_nearest_neighbour(n):
    from lampskit.core.planner_types import Stain
    from lampskit.core.stain_order import order_stains

    rng = np.random.default_rng(n)
    stains = [Stain(i, rng.uniform(0, 1, 2), 0.05) for i in range(n)]
    start = np.zeros(2)
    order = order_stains(stains, start)
    assert sorted(s.id for s in order) == list(range(n))
    length = _length_of(order, start)
    left, nn, here = list(stains), [], start
    while left:
        nxt = min(left, key=lambda s: (np.linalg.norm(s.centre_m - here), s.id))
        nn.append(nxt)
        left.remove(nxt)
        here = nxt.centre_m
    assert length <= _length_of(nn, start) + 1e-12
    for i in range(n - 1):  # no single reversal shortens it
        for j in range(i + 1, n):
            cand = order[:i] + order[i:j + 1][::-1] + order[j + 1:]
            assert _length_of(cand, start) >= length - 1e-9


def _peaks(ro, mask) -> tuple[float, float, float]:
    """Peak speed, acceleration and jerk of a rollout's samples where ``mask`` (jerk: 1 kHz differences)."""
    v = np.linalg.norm(ro.velocity_m_s, axis=1)
    a = np.linalg.norm(ro.acceleration_m_s2, axis=1)
    j = np.r_[0.0, np.linalg.norm(np.diff(ro.acceleration_m_s2, axis=0), axis=1) / np.diff(ro.t_s)]
    return float(v[mask].max()), float(a[mask].max()), float(j[mask].max())


@pytest.mark.parametrize("seed", range(8))
def test_every_planned_mp_stays_inside_the_kinematic_bounds(skill, seed):
    """1-6 stains of 3-22 cm anywhere on the board: the executed 1 kHz reference of every wipe and transition
    stays inside the planner's speed, acceleration and jerk bounds (measured on the rollout, not the plan)."""
    from lampskit.core.kinematic_bounds import BOUND_SHARE

    rng = np.random.default_rng(100 + seed)
    stains = [Stain(i, rng.uniform([0.05, 0.05], [0.65, 0.4]), float(rng.uniform(0.03, 0.22)))
              for i in range(int(rng.integers(1, 7)))]
    params = PlannerParams()
    ro = rollout(skill, plan(skill, stains, np.zeros(2), params), (np.zeros(2),) * 3)
    for kind in ("periodic", "transitional"):
        v, a, j = _peaks(ro, ro.kind == kind)
        assert v <= params.max_speed_m_s and a <= params.max_accel_m_s2 and j <= params.max_jerk_m_s3, (kind, v, a, j)
    assert all(s.within_limits for s in ro.transitions)
    assert all(max(s.peaks[0] / params.max_speed_m_s, (s.peaks[1] / params.max_accel_m_s2) ** 0.5,
                   (s.peaks[2] / params.max_jerk_m_s3) ** (1 / 3)) <= BOUND_SHARE + 1e-9 for s in ro.transitions)
    ratios = junction_step_ratios(ro)
    assert np.all(ratios[:, 2] < 3.0), ratios  # still continuous in acceleration at every hand-over


def test_without_the_bounds_a_big_stain_is_wiped_too_fast_and_the_bounds_cap_omega(skill):
    """A 20 cm stain: at the learned Omega the wipe runs at over 0.9 m/s; the bounds cap Omega exactly where the
    binding peak meets its bound, and lengthen the transition rather than sharpen it."""
    from lampskit.core.kinematic_bounds import bounded_omega, cycle_peaks
    from lampskit.core.planner import plan_transition

    stains = [Stain(0, np.array([0.3, 0.25]), 0.2), Stain(1, np.array([0.6, 0.1]), 0.05)]
    loose = PlannerParams(max_speed_m_s=2.0, max_accel_m_s2=50.0, max_jerk_m_s3=5000.0)
    fast = rollout(skill, plan(skill, stains, np.zeros(2), loose), (np.zeros(2),) * 3)
    assert _peaks(fast, fast.kind == "periodic")[0] > 0.9  # the controller brakes at 0.6 m/s
    params = PlannerParams()
    p = plan(skill, stains, np.zeros(2), params)
    w = p.wipes[0] if p.wipes[0].stain.id == 0 else p.wipes[1]
    mp = skill.periodic[w.periodic_index].mp
    cap = bounded_omega(mp, w.amplitude_m, params)
    v, a, j = cycle_peaks(mp, w.amplitude_m, cap)
    assert max(v / params.max_speed_m_s, a / params.max_accel_m_s2, j / params.max_jerk_m_s3) == pytest.approx(1.0)
    assert w.omega_rad_s < mp.omega_rad_s and w.omega_rad_s <= cap
    start = (np.zeros(2),) * 3
    bounded = plan_transition(skill, p, p.wipes[0], start)
    free = plan_transition(skill, Plan(p.wipes, loose), p.wipes[0], start)
    assert bounded.duration_s >= free.duration_s and bounded.within_limits
    # a duration given (found on the planner thread) is used as it is, without a search
    given = plan_transition(skill, p, p.wipes[0], start, duration_s=2.5)
    assert given.duration_s == 2.5 and given.goal[0] == pytest.approx(bounded.goal[0])
    with pytest.raises(PlanningError, match="duration_s"):
        plan_transition(skill, p, p.wipes[0], start, duration_s=-1.0)


@pytest.mark.parametrize("field, value", [("max_speed_m_s", 0.0), ("max_accel_m_s2", -1.0), ("max_jerk_m_s3", 1e9),
                                          ("max_transition_stretch", 0.5)])
def test_bad_bounds_are_refused_naming_them(field, value):
    with pytest.raises(PlanningError, match=field):
        PlannerParams(**{field: value})
