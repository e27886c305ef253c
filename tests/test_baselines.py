"""Fig. 6 baselines: the second-order target-crossing DMP and a ruckig trajectory."""

from __future__ import annotations

import numpy as np
import pytest

from lampskit.core.transitional import TrajectorySamples
from lampskit.core.transitional_plan import rollout, similarity_transform
from lampskit.errors import PlanningError
from lampskit.learn.baselines import (
    KinematicLimits,
    learn_target_crossing_dmp,
    limits_from_states,
    rollout_target_crossing_dmp,
    ruckig_transition,
)
from lampskit.learn.transitional_fit import learn_transitional

from .test_transitional import human_demo, random_case

DT = 0.001


@pytest.fixture(scope="module")
def demo():
    return human_demo()


@pytest.fixture(scope="module")
def third(demo):
    return learn_transitional(*demo)


@pytest.fixture(scope="module")
def second(demo):
    return learn_target_crossing_dmp(*demo)


def test_second_order_dmp_replays_its_demonstration(demo, second):
    t, y = demo
    r = rollout_target_crossing_dmp(second, second.demo_start, second.demo_goal, second.demo_duration_s, dt_s=DT)
    ref = np.column_stack([np.interp(r.t_s, t - t[0], y[:, d]) for d in range(2)])
    assert np.sqrt(np.mean(np.sum((r.position_m - ref) ** 2, axis=1))) < 1e-2
    assert np.allclose(r.position_m[0], second.demo_start[0]) and np.allclose(r.velocity_m_s[0], second.demo_start[1])


@pytest.mark.parametrize("seed", range(5))
def test_second_order_dmp_jumps_in_acceleration_at_the_start(third, second, seed):
    """It starts from (y0, v0) only: its a(0) is set by its dynamics, not by the previous MP."""
    start, goal, T = random_case(seed)
    M = similarity_transform(third.demo_displacement_m, goal[0] - start[0])
    tc = rollout_target_crossing_dmp(second, start, goal, T, dt_s=DT, forcing_transform=M)
    tmp = rollout(third, start, goal, T, dt_s=DT, forcing_transform=M)
    for r in (tc, tmp):
        assert isinstance(r, TrajectorySamples)
        assert np.allclose(r.position_m[0], start[0]) and np.allclose(r.velocity_m_s[0], start[1])
    jump_tc = np.linalg.norm(tc.acceleration_m_s2[0] - start[2])
    jump_tmp = np.linalg.norm(tmp.acceleration_m_s2[0] - start[2])
    peak = np.linalg.norm(tmp.acceleration_m_s2, axis=1).max()
    assert jump_tmp < 1e-9
    assert jump_tc > max(0.05 * peak, 1.0)  # m/s^2, an actual step for the motors
    # and at the end it arrives with the moving goal's acceleration (0), not g3
    assert np.linalg.norm(tc.acceleration_m_s2[-1] - goal[2]) > 0.1 * np.linalg.norm(goal[2])


@pytest.mark.parametrize("seed", range(5))
def test_ruckig_joins_the_same_states_in_the_same_time(seed):
    start, goal, T = random_case(seed)
    r = ruckig_transition(start, goal, T, dt_s=DT)
    assert isinstance(r, TrajectorySamples)
    assert T <= r.t_s[-1] < T + DT
    got_start = np.stack([r.position_m[0], r.velocity_m_s[0], r.acceleration_m_s2[0]])
    assert np.allclose(got_start, start, atol=1e-9)
    at_T = ruckig_transition(start, goal, T, dt_s=T)  # samples at 0 and exactly T
    got_end = np.stack([at_T.position_m[-1], at_T.velocity_m_s[-1], at_T.acceleration_m_s2[-1]])
    assert at_T.t_s[-1] == T and np.allclose(got_end, goal, atol=1e-9)
    # its outputs are derivatives of each other; its jerk is piecewise constant (bang-bang),
    # so a central difference across a switch is off by up to |jerk step| * dt / 4
    lim = limits_from_states(start, goal, T)
    inside = r.t_s <= T
    pos, vel, acc = r.position_m[inside], r.velocity_m_s[inside], r.acceleration_m_s2[inside]
    fd_vel = (pos[2:] - pos[:-2]) / (2 * DT)
    fd_acc = (vel[2:] - vel[:-2]) / (2 * DT)
    assert np.all(np.abs(fd_vel - vel[1:-1]) < 1e-4 * np.abs(vel).max() + 1e-6)
    assert np.all(np.abs(fd_acc - acc[1:-1]) <= 0.5 * lim.max_jerk_m_s3 * DT + 1e-9)
    assert np.all(np.abs(r.velocity_m_s) <= lim.max_velocity_m_s * (1 + 1e-9))
    assert np.all(np.abs(r.acceleration_m_s2) <= lim.max_acceleration_m_s2 * (1 + 1e-9))


def test_ruckig_reports_an_unreachable_target():
    start, goal, T = random_case(0)
    tight = KinematicLimits(np.full(2, 0.05), np.full(2, 1.0), np.full(2, 1.0))
    with pytest.raises(PlanningError, match="ruckig cannot reach the target state"):
        ruckig_transition(start, goal, T, limits=tight)


def test_bad_inputs_raise_planning_error(second):
    with pytest.raises(PlanningError, match="start and goal"):
        ruckig_transition(np.zeros((2, 2)), np.zeros((3, 2)), 1.0)
    with pytest.raises(PlanningError, match="duration_s"):
        rollout_target_crossing_dmp(second, np.zeros((2, 2)), np.ones((2, 2)), -1.0)
    with pytest.raises(PlanningError, match="must be finite and > 0"):
        KinematicLimits(np.zeros(2), np.ones(2), np.ones(2))
