"""Transitional MPs (paper eqs. 7-19): continuity, exact landing, learning, generalisation, files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from lampskit.core.transitional import TransitionalMP, TransitionStatus
from lampskit.core.transitional_maths import (
    N_TABLE,
    crossing_target_coefficients,
    crossing_window_s,
    forcing_term,
    fundamental_tables,
    gate_and_gains,
    phase,
)
from lampskit.core.transitional_plan import evaluate, plan_transition, rollout, similarity_transform
from lampskit.core.transitional_runner import TransitionalRunner
from lampskit.errors import LearningError, PlanningError, SkillFileError
from lampskit.learn.transitional_fit import learn_transitional

DT = 0.001


# --------------------------------------------------------------------------
# synthetic data: wiping circles and a human-like move between them


def circle_state(centre, radius_m, freq_hz, phase_rad, direction=1.0):
    """(position, velocity, acceleration) on a circle, shape (3, 2)."""
    w = 2 * np.pi * freq_hz * direction
    c, s = np.cos(phase_rad), np.sin(phase_rad)
    return np.array([centre + radius_m * np.array([c, s]), radius_m * w * np.array([-s, c]),
                     -w * w * radius_m * np.array([c, s])])


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


def human_demo(seed=1, duration_s=1.5, rate_hz=100.0, noise_m=0.0002, fade_s=0.3):
    """Leave a 1.5 Hz circle, move 0.32 m with a minimum-jerk centre, enter a 1.8 Hz circle.

    The circles fade out/in over ``fade_s`` with zero derivative at the ends,
    so the boundary states are exactly the circles' states.
    """
    rng = np.random.default_rng(seed)
    c0, c1, r = np.zeros(2), np.array([0.3, 0.1]), 0.04
    w0, w1 = 2 * np.pi * 1.5, -2 * np.pi * 1.8
    ph0, ph1 = rng.uniform(0, 2 * np.pi, 2)
    t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    centre = c0 + (c1 - c0) * _smoothstep(t / duration_s)[:, None]
    a0 = 1 - _smoothstep(t / fade_s)
    a1 = _smoothstep(1 - (duration_s - t) / fade_s)
    ring0 = r * np.stack([np.cos(ph0 + w0 * t), np.sin(ph0 + w0 * t)], 1)
    ring1 = r * np.stack([np.cos(ph1 + w1 * (t - duration_s)), np.sin(ph1 + w1 * (t - duration_s))], 1)
    y = centre + a0[:, None] * ring0 + a1[:, None] * ring1
    return t, y + noise_m * rng.standard_normal(y.shape)


def random_case(seed):
    """A realistic transition: circles r 2-6 cm at 1-2.5 Hz, 0.05-0.6 m apart, T 0.5-3 s."""
    rng = np.random.default_rng(1000 + seed)
    c0 = rng.uniform(-0.3, 0.3, 2)
    direction = rng.standard_normal(2)
    c1 = c0 + rng.uniform(0.05, 0.6) * direction / np.linalg.norm(direction)
    start, goal = (
        circle_state(c, rng.uniform(0.02, 0.06), rng.uniform(1.0, 2.5), rng.uniform(0, 2 * np.pi), rng.choice([-1, 1]))
        for c in (c0, c1)
    )
    return start, goal, float(rng.uniform(0.5, 3.0))


@pytest.fixture(scope="module")
def demo():
    return human_demo()


@pytest.fixture(scope="module")
def mp(demo):
    return learn_transitional(*demo)


def run(runner, dt=DT):
    """Step a runner to the end; returns times, states (m, 3, n) while working, and the first finished state."""
    t, states = [0.0], [np.stack([runner.position_m, runner.velocity_m_s, runner.acceleration_m_s2]).copy()]
    while runner.update(dt) == TransitionStatus.WORKING:
        t.append(runner.time_s)
        states.append(np.stack([runner.position_m, runner.velocity_m_s, runner.acceleration_m_s2]).copy())
    final = np.stack([runner.position_m, runner.velocity_m_s, runner.acceleration_m_s2]).copy()
    return np.array(t), np.array(states), final


def mapped(mp, start, goal):
    return similarity_transform(mp.demo_displacement_m, goal[0] - start[0])


# --------------------------------------------------------------------------
# the maths


def test_gains_give_a_critically_damped_triple_pole():
    """(18)-(19): alpha=3p, beta=p, gamma=p/3 -> P(s) = (s + p/tau)^3."""
    p, tau = 17.0, 1.3
    _, gains = gate_and_gains(np.zeros(1), p, 1.0)
    alpha, beta, gamma = 3 * p, p, p / 3
    assert np.allclose(gains, [alpha * beta * gamma, alpha * beta, alpha])
    roots = np.roots([1.0, alpha / tau, alpha * beta / tau**2, alpha * beta * gamma / tau**3])
    assert np.allclose(roots, -p / tau, atol=1e-3 * p / tau)


@pytest.mark.parametrize("sigma", [0.07, math.inf])
def test_crossing_target_arrives_at_the_entry_state_and_is_differentiated_correctly(sigma):
    goal = np.array([[0.3, -0.1], [0.8, 0.2], [-12.0, 5.0]])
    at_end = crossing_target_coefficients(np.array([0.0]), sigma)[0] @ goal
    assert np.allclose(at_end[:3], goal, atol=1e-15)
    u = np.linspace(-0.4, -0.01, 500)
    h = 1e-6
    c, cp, cm = (crossing_target_coefficients(u + d, sigma) @ goal for d in (0.0, h, -h))
    for k in range(3):  # each row is the derivative of the one above
        assert np.allclose((cp[:, k] - cm[:, k]) / (2 * h), c[:, k + 1], rtol=1e-5, atol=1e-4)


def test_crossing_window_bounds_the_target_excursion():
    goal = circle_state(np.zeros(2), 0.06, 2.5, 0.3)  # |g2| ~ 0.94 m/s, |g3| ~ 15 m/s^2
    sigma = crossing_window_s(goal, 3.0, 0.1)
    assert 0 < sigma <= 3.0 / 4
    target = crossing_target_coefficients(np.linspace(-3, 0, 3001), sigma)[:, 0] @ goal
    assert np.linalg.norm(target - goal[0], axis=1).max() < 0.1 * 1.01
    assert crossing_window_s(goal, 3.0, math.inf) == math.inf


def test_tables_match_an_independent_integrator(mp):
    """The RK4 fundamental solutions agree with scipy's DOP853 at tight tolerance."""
    e0 = np.array([0.01, -0.3, 2.0])
    phi, forced = fundamental_tables(mp.p, mp.lambda_, mp.weights, mp.centres, mp.widths)
    gains = np.array([mp.p**3, 3 * mp.p**2, 3 * mp.p])

    def rhs(s, e):
        f = forcing_term(np.array([phase(s, mp.lambda_)]), mp.weights[:, :1], mp.centres, mp.widths)[0, 0]
        return [e[1], e[2], -(1 - phase(s, mp.lambda_)) * gains @ e + f]

    ref = solve_ivp(rhs, (0.0, 1.0), e0, method="DOP853", rtol=1e-11, atol=1e-12, t_eval=[0.5, 1.0])
    for col, s in ((N_TABLE // 2, 0), (N_TABLE, 1)):
        got = phi[col, :3] @ e0 + forced[col, :3, 0]
        assert np.allclose(got, ref.y[:, s], rtol=1e-6, atol=1e-7 * np.abs(ref.y).max())


# --------------------------------------------------------------------------
# generalisation: the properties the planner relies on


@pytest.mark.parametrize("seed", range(8))
def test_continuity_at_both_junctions_and_exact_landing(mp, seed):
    start, goal, T = random_case(seed)
    runner = TransitionalRunner(mp, start, goal, T, forcing_transform=mapped(mp, start, goal))
    t, states, first_finished = run(runner)
    acc = states[:, 2]
    peak = np.linalg.norm(acc, axis=1).max()
    tick = np.linalg.norm(np.diff(acc, axis=0), axis=1)
    # start: the exact state, and no step larger than the transition's own per-tick change
    assert np.array_equal(states[0], start)
    assert np.allclose(evaluate(runner.plan, [0.0])[1:], [start[0:1], start[1:2], start[2:3]], atol=1e-12)
    assert tick[0] <= tick[1:].max() + 1e-9
    # end: left limit at T within 1 mm, 1 mm/s and 1 % of the peak acceleration
    left = evaluate(runner.plan, [T * (1 - 1e-12)])
    assert np.linalg.norm(left.position_m[0] - goal[0]) < 1e-3
    assert np.linalg.norm(left.velocity_m_s[0] - goal[1]) < 1e-3
    assert np.linalg.norm(left.acceleration_m_s2[0] - goal[2]) <= 0.01 * peak
    # the hand-over tick: no acceleration step beyond the trajectory's own per-tick change
    assert np.linalg.norm(first_finished[2] - acc[-1]) <= tick.max() + 1e-9
    assert abs(runner.time_s - T) < DT + 1e-12 and 0 <= runner.overrun_s < DT + 1e-12


@pytest.mark.parametrize("seed", range(4))
def test_output_derivatives_match_finite_differences(mp, seed):
    start, goal, T = random_case(seed)
    _, states, _ = run(TransitionalRunner(mp, start, goal, T, forcing_transform=mapped(mp, start, goal)))
    pos, vel, acc = states[:, 0], states[:, 1], states[:, 2]
    fd_vel = (pos[2:] - pos[:-2]) / (2 * DT)
    fd_acc = (vel[2:] - vel[:-2]) / (2 * DT)
    assert np.abs(fd_vel - vel[1:-1]).max() <= 2e-4 * np.abs(vel).max() + 1e-6
    assert np.abs(fd_acc - acc[1:-1]).max() <= 2e-3 * np.abs(acc).max() + 1e-6


def test_runner_is_exact_for_any_step_and_agrees_with_evaluate(mp):
    start, goal, T = random_case(3)
    M = mapped(mp, start, goal)
    t1, s1, _ = run(TransitionalRunner(mp, start, goal, T, M), 0.001)
    t2, s2, _ = run(TransitionalRunner(mp, start, goal, T, M), 0.0005)
    assert np.allclose(s1[10:-10], s2[20:-20:2], atol=1e-9)
    ev = evaluate(plan_transition(mp, start, goal, T, M), t1)
    assert np.allclose(np.stack([ev.position_m, ev.velocity_m_s, ev.acceleration_m_s2], 1), s1, atol=1e-10)


def test_transition_stays_near_the_move_for_realistic_cases(mp):
    """Not a loop of metres (the paper's unwindowed target does that): bounded by move, circles and reach."""
    for seed in range(8):
        start, goal, _ = random_case(seed)
        dist = np.linalg.norm(goal[0] - start[0])
        T = max(0.5, dist / (np.linalg.norm(mp.demo_displacement_m) / mp.demo_duration_s))
        r = rollout(mp, start, goal, T, forcing_transform=mapped(mp, start, goal))
        d = goal[0] - start[0]
        along = np.clip((r.position_m - start[0]) @ d / (d @ d), 0, 1)
        off = np.linalg.norm(r.position_m - start[0] - along[:, None] * d, axis=1)
        assert off.max() < 0.3 * dist + 0.15


def test_forcing_switched_off_and_three_dimensions_still_land_exactly():
    t, y2 = human_demo(seed=4)
    y = np.column_stack([y2, 0.05 * np.sin(np.linspace(0, np.pi, len(t)))])
    mp3 = learn_transitional(t, y)
    assert mp3.weights.shape == (mp3.n_basis, 3)
    rng = np.random.default_rng(7)
    start = rng.normal(size=(3, 3)) * [[0.1], [0.5], [5.0]]
    goal = rng.normal(size=(3, 3)) * [[0.1], [0.5], [5.0]]
    for M in (None, np.zeros((3, 3))):
        plan = plan_transition(mp3, start, goal, 1.2, M)
        end = evaluate(plan, [1.2 * (1 - 1e-12)])
        assert np.allclose([end.position_m[0], end.velocity_m_s[0], end.acceleration_m_s2[0]], goal, atol=1e-8)


# --------------------------------------------------------------------------
# learning


def test_learned_mp_reproduces_its_demonstration(demo, mp):
    t, y = demo
    assert mp.demo_rmse_m < 1e-3  # noise is 0.2 mm
    runner = TransitionalRunner(mp, mp.demo_start, mp.demo_goal, mp.demo_duration_s)
    times, states, _ = run(runner)
    ref = np.column_stack([np.interp(times, t - t[0], y[:, d]) for d in range(2)])
    rmse = np.sqrt(np.mean(np.sum((states[:, 0] - ref) ** 2, axis=1)))
    assert rmse < 1e-3
    assert abs(rmse - mp.demo_rmse_m) < 3e-4
    assert np.allclose(mp.demo_displacement_m, mp.demo_goal[0] - mp.demo_start[0])
    # boundary states are the circles' (to the accuracy of differentiating 0.2 mm noise)
    assert np.linalg.norm(mp.demo_start[0] - y[0]) < 1e-3 and np.linalg.norm(mp.demo_goal[0] - y[-1]) < 1e-3


def test_classic_lwr_fit_also_reproduces_the_demonstration(demo):
    """The classic eq.-(13) forcing target + LWR: works, but millimetres, not tenths (see docs)."""
    mp_lwr = learn_transitional(*demo, regression="lwr", n_basis=150)
    assert mp_lwr.demo_rmse_m < 1e-2


def test_rigid_motion_of_the_demonstration_is_reproduced_exactly(mp):
    """forcing_transform = R with start/goal rotated and shifted -> the rotated, shifted demo replay."""
    angle = 2.1
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    shift = np.array([0.4, -0.2])
    start = mp.demo_start @ R.T + [shift, 0 * shift, 0 * shift]
    goal = mp.demo_goal @ R.T + [shift, 0 * shift, 0 * shift]
    times = np.linspace(0, mp.demo_duration_s, 200)
    ref = evaluate(plan_transition(mp, mp.demo_start, mp.demo_goal, mp.demo_duration_s), times)
    new = evaluate(plan_transition(mp, start, goal, mp.demo_duration_s, R), times)
    assert np.allclose(new.position_m, ref.position_m @ R.T + shift, atol=1e-9)
    assert np.allclose(new.acceleration_m_s2, ref.acceleration_m_s2 @ R.T, atol=1e-7)


def test_similarity_and_time_scaling_map_the_replay(demo):
    """With the unwindowed target (reach = inf) the MP is equivariant under s R and T -> k T."""
    mp_inf = learn_transitional(*demo, crossing_reach_m=math.inf)
    sR = 1.7 * np.array([[0.0, -1.0], [1.0, 0.0]])
    k = 1.6  # new duration / demo duration
    scale_rows = np.array([[1.0], [1.0 / k], [1.0 / k**2]])
    start = (mp_inf.demo_start @ sR.T) * scale_rows
    goal = (mp_inf.demo_goal @ sR.T) * scale_rows
    times = np.linspace(0, mp_inf.demo_duration_s, 150)
    ref = evaluate(plan_transition(mp_inf, mp_inf.demo_start, mp_inf.demo_goal, mp_inf.demo_duration_s), times)
    new = evaluate(plan_transition(mp_inf, start, goal, k * mp_inf.demo_duration_s, sR), k * times)
    assert np.allclose(new.position_m, ref.position_m @ sR.T, atol=1e-8)
    assert np.allclose(new.velocity_m_s, ref.velocity_m_s @ sR.T / k, atol=1e-7)


@pytest.mark.parametrize(
    "t, y, match",
    [
        (np.arange(5) * 0.01, np.zeros((5, 2)), "too short: 5 samples"),
        (np.arange(20) * 0.001, np.zeros((20, 2)), "too short: 0.019 s"),
        (np.arange(50) * 0.01, np.where(np.arange(100).reshape(50, 2) == 7, np.nan, 0.0), "NaN or inf"),
        (np.r_[np.arange(25), np.arange(25)] * 0.01, np.zeros((50, 2)), "increase strictly"),
        (np.arange(50) * 0.01, np.zeros((49, 2)), "must have shape"),
    ],
)
def test_unusable_segments_raise_learning_error(t, y, match):
    with pytest.raises(LearningError, match=match):
        learn_transitional(t, y)


def test_bad_learning_parameters_raise(demo):
    with pytest.raises(LearningError, match="regression"):
        learn_transitional(*demo, regression="magic")
    with pytest.raises(LearningError, match="n_basis"):
        learn_transitional(*demo, n_basis=1)


# --------------------------------------------------------------------------
# step API and validation


def test_runner_status_and_hold_after_the_end(mp):
    start, goal, T = random_case(1)
    runner = TransitionalRunner(mp, start, goal, T)
    assert runner.status == TransitionStatus.WORKING and not runner.finished
    before = runner.position_m.copy()
    for bad in (0.0, -1e-3, math.nan, math.inf):
        assert runner.update(bad) == TransitionStatus.ERROR_INVALID_INPUT
    assert runner.time_s == 0.0 and np.array_equal(runner.position_m, before)
    while runner.update(DT) == TransitionStatus.WORKING:
        pass
    assert runner.finished
    assert runner.update(0.05) == TransitionStatus.FINISHED
    u = runner.time_s - T
    assert np.allclose(runner.position_m, goal[0] + u * goal[1] + 0.5 * u * u * goal[2], atol=1e-12)
    assert np.allclose(runner.acceleration_m_s2, goal[2])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(start=np.zeros((2, 2))), "start must be"),
        (dict(goal=np.full((3, 2), np.nan)), "goal contains NaN"),
        (dict(duration_s=0.0), "duration_s must be"),
        (dict(duration_s=math.nan), "duration_s must be"),
        (dict(forcing_transform=np.eye(3)), "forcing_transform must be"),
    ],
)
def test_bad_plans_raise_planning_error(mp, kwargs, match):
    args = dict(start=np.zeros((3, 2)), goal=np.ones((3, 2)), duration_s=1.0, forcing_transform=None)
    args.update(kwargs)
    with pytest.raises(PlanningError, match=match):
        TransitionalRunner(mp, **args)


@pytest.mark.parametrize("dims", [1, 2, 3])
def test_similarity_transform_maps_one_vector_onto_another(dims):
    rng = np.random.default_rng(dims)
    a, b = rng.normal(size=dims), rng.normal(size=dims)
    M = similarity_transform(a, b)
    assert np.allclose(M @ a, b)
    assert np.allclose(M.T @ M, (np.linalg.norm(b) / np.linalg.norm(a)) ** 2 * np.eye(dims))
    assert np.allclose(similarity_transform(a, -a) @ a, -a)


# --------------------------------------------------------------------------
# files


def test_round_trip_through_json_gives_the_same_transitions(mp):
    again = TransitionalMP.from_dict(json.loads(json.dumps(mp.to_dict())))
    assert again.to_dict() == mp.to_dict()
    start, goal, T = random_case(2)
    a, b = rollout(mp, start, goal, T), rollout(again, start, goal, T)
    assert np.array_equal(a.position_m, b.position_m)
    inf_mp = TransitionalMP.from_dict({**mp.to_dict(), "crossing_reach_m": "inf"})
    assert math.isinf(inf_mp.crossing_reach_m) and inf_mp.to_dict()["crossing_reach_m"] == "inf"


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda d: d.update(weights=[[1.0, float("nan")]] * len(d["weights"])), "weights: contains NaN"),
        (lambda d: d.update(centres=d["centres"][:-1]), r"centres: expected shape"),
        (lambda d: d.update(widths=[-1.0] * len(d["widths"])), "widths: every width"),
        (lambda d: d.update(p=500.0), r"p: must be in"),
        (lambda d: d.update(p=[1.0, 2.0]), r"p: expected a number"),
        (lambda d: d.update({"lambda": "fast"}), r"lambda: expected a number"),
        (lambda d: d.update(demo_goal=[[0.0, 0.0]]), r"demo_goal: expected shape \(3, 2\)"),
        (lambda d: d.update(demo_duration_s=-1.0), "demo_duration_s"),
        (lambda d: d.update(demo_start="abc"), "demo_start"),
        (lambda d: d.pop("lambda"), r"missing field\(s\) \['lambda'\]"),
        (lambda d: d.update(kind="periodic_mp"), "kind must be"),
        (lambda d: d.update(version=99), "unsupported version 99"),
    ],
)
def test_malformed_files_raise_skill_file_error_naming_the_field(mp, change, match):
    d = mp.to_dict()
    change(d)
    with pytest.raises(SkillFileError, match=match):
        TransitionalMP.from_dict(d)


@pytest.mark.realdata
def test_real_segments_are_reproduced():
    """The labelled approach/retract segments of the four real wiping demos (skipped without the data)."""
    from scipy.io import loadmat

    from .conftest import REAL_DEMOS

    if not REAL_DEMOS.exists():
        pytest.skip(f"{REAL_DEMOS} not present")
    data = loadmat(REAL_DEMOS, squeeze_me=True, struct_as_record=False)
    for demo_, labels in zip(data["proc_data"], data["True_states"]):
        pos, t = demo_.X[:3].T, np.arange(demo_.X.shape[1]) * demo_.dt
        for label in (1, 3):  # approach, retract
            idx = np.flatnonzero(labels == label)
            idx = max(np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1), key=len)
            mp_real = learn_transitional(t[idx], pos[idx])
            assert mp_real.demo_rmse_m < 5e-4
