"""The pad's half turn about its normal (arm/pad_turn.py): A7 by pi on the real description, the way it turns, the
free motion that makes it, and random board 396, whose wrist took the branch where the pad needs A7 at its limit."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from arm.pad_turn import ENOUGH_ROOM_RAD, half_turn_way, half_turned, joint_room_rad, turn_vector
from arm.robot_model import RobotModel
from controller.executor_types import ToolState
from controller.free_motion import FreeMotion
from controller.motion import OrientationBlend
from controller.params import ExecutorParams, ForceParams


@pytest.fixture(scope="module")
def model():
    return RobotModel()


def test_a7_turned_by_pi_is_the_pad_turned_half_about_its_normal_and_nothing_else(model):
    """The premise, on the iiwa's description: the pad's centre on A7's axis, its z along it."""
    rng = np.random.default_rng(7)
    lo, hi = model.limits.q_min, model.limits.q_max
    for _ in range(20):
        q = rng.uniform(0.8 * lo, 0.8 * hi)
        q[-1] = rng.uniform(-0.1, 0.1)
        p0, R0 = model.tcp_pose(q)
        for way in (1.0, -1.0):
            turned = q.copy()
            turned[-1] += way * math.pi
            p1, R1 = model.tcp_pose(turned)
            assert np.allclose(p1, p0, atol=1e-9) and np.allclose(R1, half_turned(R0), atol=1e-9)
            # and the turn's way: a small step of A7 turns the pad positively about its own z
            step = q.copy()
            step[-1] += 1e-3
            assert pin.log3(R0.T @ model.tcp_pose(step)[1])[2] == pytest.approx(1e-3, rel=1e-6)


def test_the_half_turn_takes_a7_to_the_middle_only_when_that_gives_the_joints_room(model):
    lo, hi = model.limits.q_min, model.limits.q_max
    # board 396 over its stain, measured: A7 0.10 rad from its limit
    q = np.array([0.74, 0.78, -0.55, -1.30, 1.42, -0.42, -2.95])
    assert joint_room_rad(q, lo, hi) == pytest.approx(0.104, abs=1e-3)
    assert half_turn_way(q, lo, hi) == 1.0
    assert half_turn_way(-q, lo, hi) == -1.0
    # every joint roomy: nothing to do
    assert half_turn_way(np.array([0.5, 0.8, -0.5, -1.3, 1.0, -0.8, -1.5]), lo, hi) == 0.0
    # A1 at its limit (random board 245): the half turn moves A7 only, gains nothing, is not made
    assert half_turn_way(np.array([2.9, 0.8, -0.5, -1.3, 1.0, -0.8, -2.0]), lo, hi) == 0.0
    # A7 in its zone, the turn would free it, but A5 stands as near its own limit: not made
    q = np.array([0.5, 0.8, -0.5, -1.3, 2.6, -0.8, 2.7])
    assert joint_room_rad(q, lo, hi) < ENOUGH_ROOM_RAD and half_turn_way(q, lo, hi) == 0.0
    q[4] = 1.0  # A5 roomy: now it is, A7 down towards its middle
    assert half_turn_way(q, lo, hi) == -1.0


def test_turn_vector_goes_the_way_it_is_asked_round_the_pads_z():
    R0 = pin.rpy.rpyToMatrix(0.3, -0.2, 1.1)
    R1 = half_turned(R0) @ pin.exp3(np.array([0.02, -0.01, 0.05]))  # a half turn and a little more
    for way in (1.0, -1.0):
        theta = turn_vector(R0, R1, way)
        assert theta[2] * way > 3.0 and np.allclose(R0 @ pin.exp3(theta), R1, atol=1e-9)
    shortest = turn_vector(R0, R0 @ pin.exp3(np.array([0.1, 0.0, 0.2])))
    assert np.allclose(shortest, [0.1, 0.0, 0.2])
    assert np.allclose(turn_vector(R0, half_turned(R0), -1.0), [0.0, 0.0, -math.pi], atol=1e-9)
    # the blend passes a quarter turn the way asked at its middle
    blend = OrientationBlend(R0, half_turned(R0), 2.0, about_z=-1.0)
    blend.update(1.0)
    assert np.allclose(blend.R, R0 @ pin.exp3(np.array([0.0, 0.0, -0.5 * math.pi])), atol=1e-9)


def test_the_free_motion_turns_the_pad_half_from_the_joints_it_measures(model):
    motion = FreeMotion(ExecutorParams(), ForceParams())
    R = pin.rpy.rpyToMatrix(math.pi, 0.0, 0.4)
    motion.hold_here(ToolState(np.zeros(2), 0.05, np.zeros(2), 0.0, R, 0.0))
    assert not motion.turn_half_if_cramped()  # joints not known: nothing
    q = np.array([0.74, 0.78, -0.55, -1.30, 1.42, -0.42, -2.95])
    motion.joints, motion.joint_limits = q, (model.limits.q_min, model.limits.q_max)
    assert motion.turn_half_if_cramped() and motion.turning and motion.counters["pad_half_turns"] == 1
    T = math.pi / ExecutorParams().turn_rate_rad_s
    steps = 0
    while motion.turning:
        motion.step_turn(1e-3)
        steps += 1
        if steps == round(0.5 * T * 1e3):  # halfway: a quarter turn positively about the pad's z (A7 up)
            assert pin.log3(R.T @ motion.setpoint.R)[2] == pytest.approx(0.5 * math.pi, abs=1e-3)
    assert steps == pytest.approx(T * 1e3, abs=2)
    assert np.allclose(motion.setpoint.R, half_turned(R), atol=1e-9)
    motion.joints[-1] += math.pi  # where the arm's A7 went
    assert not motion.turn_half_if_cramped()


@pytest.mark.slow
def test_random_board_396_turns_the_pad_half_and_cleans_its_stain(tmp_path):
    """``lamps up --no-network --board random:396 --stains 1 --seed 396``: over the stain A7 stood 0.10 rad from its
    limit, the pad 25 mm off its reference; turned half before the descent, the stain is wiped."""
    from .test_arm_clearance import run_random_board

    report, stdout, sim = run_random_board(tmp_path, 396, 1, first_start=True)
    assert report["outcome"] == "cleaned", (report["outcome"], report.get("final_reason"), stdout[-3000:])
    assert report["dirt_removed_fraction"] >= 0.98 and not report["faults"], report["faults"]
    assert report["counters"]["controller"]["pad_half_turns"] == 1, report["counters"]["controller"]
    assert not {k: v for k, v in sim.items() if ("brake" in k or "yield" in k or "fault" in k) and v}, sim
    assert report["max_joint_speed_ratio"] < 0.8
