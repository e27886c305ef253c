"""The rest posture planned out of the clearance's zones (arm.posture) and carried there off the tick
(controller.rest_posture), on the real Pinocchio model, from the start poses the simulator gives random boards."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from arm.posture import ClearanceZones, clearance_gradient, clearance_potential, planned_rest_posture
from arm.robot_model import RobotModel
from controller.params import LimitParams
from controller.rest_posture import RestPosture, rest_posture_for
from sim.board import board_from_params, start_configuration
from sim.board_sampler import sample_board
from sim.params import BoardParams, SimParams
from tests.test_arm_clearance import run_random_board

#: Random board 322 as the sampler draws it (kept literal: the test stays on this board whatever the sampler does).
BOARD_322 = {"preset": "custom", "origin_m": [0.222721, 0.409078, 0.295604],
             "quat_wxyz": [0.77781066, 0.156203085, -0.368050564, -0.484922628], "size_m": [0.7644, 0.4604]}


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel()


def zones(model: RobotModel) -> ClearanceZones:
    singular = np.zeros(model.nq)
    singular[[1, 3, 5]] = 1.0
    return ClearanceZones(0.5, singular, 0.6)


def start_of(seed: int, model: RobotModel) -> np.ndarray:
    """The simulator's start pose on random board ``seed`` (as ``lamps up --board random:seed`` starts)."""
    board = board_from_params(BoardParams(**sample_board(seed, model).table))
    return start_configuration(board, SimParams().start_standoff_m, model)


def test_the_gradient_is_the_potentials(model: RobotModel) -> None:
    """The descent follows the clearance's own push: the gradient matches the potential's finite differences."""
    z = zones(model)
    lo, hi = model.limits.q_min, model.limits.q_max
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.uniform(lo, hi)
        g = clearance_gradient(q, lo, hi, z)
        e = 1e-6
        fd = np.array([(clearance_potential(q + e * np.eye(7)[i], lo, hi, z)
                        - clearance_potential(q - e * np.eye(7)[i], lo, hi, z)) / (2 * e) for i in range(7)])
        np.testing.assert_allclose(g, fd, atol=1e-5)


@pytest.mark.parametrize("seed", [245, 322])
def test_a_start_inside_the_singular_zones_is_planned_out_of_them_holding_the_pad(model: RobotModel,
                                                                                 seed: int) -> None:
    """Random boards 245 and 322 start the arm with A2 (and on 245 A6) inside the singular clearance's zone; at
    that start the controller's clearance carried A1 (322) or A7 (245) onto its limit. The plan holds the pad
    where it is, keeps the branch (the signs of A2 and A6) and leaves A2 and A6 out of their zones, every joint
    at least 0.3 rad inside its limits or no closer than it started (A4, the elbow, is fixed by the pad pose)."""
    q0 = start_of(seed, model)
    z = zones(model)
    assert min(abs(q0[1]), abs(q0[5])) < 0.6  # the premise: the start is inside a zone
    q = planned_rest_posture(model, q0, z)
    p0, R0 = model.tcp_pose(q0)
    p, R = model.tcp_pose(q)
    assert np.linalg.norm(p - p0) < 1e-3
    assert np.degrees(np.arccos(np.clip((np.trace(R0.T @ R) - 1) / 2, -1, 1))) < 0.1
    assert np.sign(q[1]) == np.sign(q0[1]) and np.sign(q[5]) == np.sign(q0[5])
    assert abs(q[1]) >= 0.59 and abs(q[5]) >= 0.59
    lo, hi = model.limits.q_min, model.limits.q_max
    room, room0 = np.minimum(q - lo, hi - q), np.minimum(q0 - lo, hi - q0)
    assert np.all(room >= np.minimum(0.3, room0 - 1e-6))
    assert clearance_potential(q, lo, hi, z) < 0.5 * clearance_potential(q0, lo, hi, z)


def test_a_start_out_of_every_zone_is_its_own_plan(model: RobotModel) -> None:
    q0 = np.array([0.2, 0.9, -0.3, -1.5, 0.4, 1.0, 0.1])
    z = zones(model)
    assert clearance_potential(q0, model.limits.q_min, model.limits.q_max, z) == 0.0
    np.testing.assert_array_equal(planned_rest_posture(model, q0, z), q0)


def test_the_rest_pose_moves_to_the_plan_at_its_rate_off_the_tick(model: RobotModel) -> None:
    """The rest pose is the first state until the plan answers (here on a thread, as the planner thread runs
    it), then moves at most ``rate * dt`` per joint per tick and stops on the plan; an arm held at its start
    (in the zone all along) is planned again every second, to the same plan."""
    q0 = start_of(322, model)
    posture = rest_posture_for(model, LimitParams())
    dt, rate = 0.001, LimitParams().rest_plan_rate_rad_s
    with ThreadPoolExecutor(1) as pool:
        posture.job.executor = pool
        posture.begin(q0)
        np.testing.assert_array_equal(posture.q, q0)
        while posture.job.busy:
            np.testing.assert_array_equal(posture.q, q0)  # nothing moves before the plan answers
            posture.step(q0, dt)
        assert posture.goal is not None
        goal, q_first_step = posture.goal.copy(), posture.q.copy()
        assert np.max(np.abs(q_first_step - q0)) <= rate * dt + 1e-12
        ticks, plans = 0, 0
        while not np.array_equal(posture.q, posture.goal):
            before = posture.q.copy()
            posture.step(q0, dt)
            plans += posture.job.busy
            while posture.job.busy:  # a re-plan: wait for it as a later tick would
                posture.step(q0, 0.0)
            assert np.max(np.abs(posture.q - before)) <= rate * dt + 1e-12
            np.testing.assert_array_equal(posture.goal, goal)
            ticks += 1
        assert ticks + 1 == pytest.approx(np.max(np.abs(goal - q0)) / (rate * dt), abs=2)
        assert plans == pytest.approx(ticks * dt / posture.replan_s, abs=1)
        assert posture.plans == plans + 1 and posture.plans_in_zone == plans  # what the status counts
    posture.reset()
    assert posture.q is None and posture.goal is None


def test_the_rest_pose_is_planned_again_only_while_the_arm_stands_in_a_zone(model: RobotModel) -> None:
    """Where the pad went on, the arm may stand in a zone again (board 51: A6 back at 0.01): a second later the
    rest pose is planned from there. Out of every zone the last plan stays."""
    q0 = start_of(322, model)
    posture = rest_posture_for(model, LimitParams())
    posture.begin(q0)  # no executor: the plan answers at once, as in lock-step
    first = posture.goal.copy()
    elsewhere = start_of(245, model)  # A2 and A6 inside their zones
    free = np.array([0.2, 0.9, -0.3, -1.5, 0.4, 1.0, 0.1])
    for _ in range(1500):
        posture.step(free, 0.001)
    np.testing.assert_array_equal(posture.goal, first)
    assert (posture.plans, posture.plans_in_zone) == (1, 0)
    for _ in range(1001):
        posture.step(elsewhere, 0.001)
    np.testing.assert_allclose(posture.goal, planned_rest_posture(model, elsewhere, zones(model)))
    assert (posture.plans, posture.plans_in_zone) == (2, 1)
    p_goal, _ = model.tcp_pose(posture.goal)
    np.testing.assert_allclose(p_goal, model.tcp_pose(elsewhere)[0], atol=1e-3)


def test_no_plan_when_the_clearance_or_the_rate_is_off(model: RobotModel) -> None:
    q0 = start_of(322, model)
    for limits in (LimitParams(rest_plan_rate_rad_s=0.0), LimitParams(clearance_stiffness_nm_rad=0.0)):
        posture = rest_posture_for(model, limits)
        posture.begin(q0)
        for _ in range(100):
            posture.step(posture.q, 0.001)
        np.testing.assert_array_equal(posture.q, q0)
    with pytest.raises(ValueError, match="rate"):
        RestPosture(None, 0.0)


def test_board_322_is_the_sampler_s():
    assert sample_board(322).table == BOARD_322


@pytest.mark.slow
def test_board_322_starting_with_a2_in_its_zone_cleans_tracking_its_reference(tmp_path: Path) -> None:
    """The arm starts with A2 at -0.08 rad. With the first state as the rest pose, the clearance swung A1 onto its
    limit: tracking 42 mm RMS, a stain given up after six passes, 94.7 % of the dirt. With the planned rest pose:
    cleaned, the pad on its reference, no robot-side brake, every joint under 0.8 of its speed limit, under 20 N."""
    report, stdout, sim = run_random_board(tmp_path, 322, 5, BOARD_322, first_start=True)
    assert report["outcome"] == "cleaned", (report["outcome"], report["final_reason"], stdout[-3000:])
    assert report["tracking_rms_m"] < 0.01, report["tracking_rms_m"]
    assert not {k: v for k, v in sim.items() if ("brake" in k or "yield" in k or "fault" in k) and v}, sim
    assert report["max_joint_speed_ratio"] < 0.8 and report["peak_contact_force_n"] < 20.0
