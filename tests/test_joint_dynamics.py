"""Rotor inertia and joint friction: one set of figures in Pinocchio's model and in the simulated drives."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from arm.joint_dynamics import (
    COULOMB_NM,
    FR3_REFLECTED_INERTIA_KG_M2,
    JointDynamics,
    friction_torque,
    joint_dynamics_from_config,
)
from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from sim.core import SimCore
from sim.drive import drive_torque
from sim.params import SimParams

RIGID = JointDynamics(armature_kg_m2=(0.0,) * 7, viscous_nm_s_rad=(0.0,) * 7, coulomb_nm=(0.0,) * 7)
ARMATURE_ONLY = JointDynamics(armature_kg_m2=FR3_REFLECTED_INERTIA_KG_M2, viscous_nm_s_rad=(0.0,) * 7,
                              coulomb_nm=(0.0,) * 7)
Q = np.array([0.56, 0.30, -0.66, -1.90, -0.14, -0.59, -1.27])


def _symmetric(M: np.ndarray) -> np.ndarray:
    """Pinocchio fills the upper triangle only."""
    return np.triu(M) + np.triu(M, 1).T


def _sim(joints: JointDynamics) -> SimCore:
    """A gravity-compensating sim at rest, away from the board, whose drives have ``joints``."""
    return SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}),
                   RobotModel(joints=joints))


# -- Pinocchio -----------------------------------------------------------------------------------------------

def test_pinocchio_inertia_carries_the_armature_on_its_diagonal():
    rigid, geared = RobotModel(joints=RIGID), RobotModel(joints=ARMATURE_ONLY)
    M0 = _symmetric(pin.crba(rigid.model, rigid.data, Q))
    M1 = _symmetric(pin.crba(geared.model, geared.data, Q))
    np.testing.assert_allclose(M1 - M0, np.diag(FR3_REFLECTED_INERTIA_KG_M2), atol=1e-12)
    M1_inv = _symmetric(pin.computeMinverse(geared.model, geared.data, Q))
    np.testing.assert_allclose(M1_inv @ M1, np.eye(7), atol=1e-10)


def test_the_model_carries_the_friction_figures_and_defaults_to_the_cited_ones():
    m = RobotModel()
    np.testing.assert_array_equal(m.model.armature, JointDynamics().armature_kg_m2)
    np.testing.assert_array_equal(m.model.damping, JointDynamics().viscous_nm_s_rad)
    np.testing.assert_array_equal(m.model.friction, COULOMB_NM)


# -- the friction law and the torque path ----------------------------------------------------------------------

def test_friction_slope_is_the_derivative_of_the_friction_torque():
    jd = JointDynamics()
    dq = np.array([-0.3, -0.002, -0.0005, 0.0, 0.0007, 0.003, 0.2])
    tau_f, slope = friction_torque(dq, jd)
    h = 1e-7
    numeric = (friction_torque(dq + h, jd)[0] - friction_torque(dq - h, jd)[0]) / (2 * h)
    np.testing.assert_allclose(slope, numeric, rtol=1e-6, atol=1e-6)
    assert np.all(tau_f * dq >= 0.0)  # it resists the motion
    np.testing.assert_allclose(friction_torque(np.full(7, 1.0), jd)[0],
                               np.add(jd.viscous_nm_s_rad, jd.coulomb_nm), rtol=1e-9)


def test_drive_torque_gives_pybullets_inertia_the_acceleration_of_the_geared_arm_with_friction():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(7, 7))
    M = A @ A.T + 7 * np.eye(7)
    tau, h_hat, dq = rng.normal(size=7), rng.normal(size=7), np.array([-0.2, -0.003, 0.0, 0.001, 0.004, 0.3, 1.0])
    for jd in (ARMATURE_ONLY, JointDynamics(armature_kg_m2=FR3_REFLECTED_INERTIA_KG_M2)):
        tau_pb = drive_torque(tau, dq, M, h_hat, jd, 1e-3)
        tau_f, slope = friction_torque(dq, jd)
        # the numpy formulation of the linearly implicit step (sim/drive.py)
        expected = np.linalg.solve(M + np.diag(np.add(jd.armature_kg_m2, 1e-3 * slope)), tau - tau_f - h_hat)
        np.testing.assert_allclose(np.linalg.solve(M, tau_pb - h_hat), expected, rtol=1e-10, atol=1e-12)
    with pytest.raises(ValueError, match="dt_s must be positive"):
        drive_torque(tau, dq, M, h_hat, ARMATURE_ONLY, 0.0)
    with pytest.raises(ValueError, match="not positive definite"):
        drive_torque(tau, dq, -M, h_hat, ARMATURE_ONLY, 1e-3)


# -- PyBullet ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("joint, torque_nm", [(0, 20.0), (3, 10.0), (6, 2.0)])
def test_a_step_torque_from_rest_accelerates_the_arm_through_m_plus_armature(joint, torque_nm):
    core = _sim(ARMATURE_ONLY)
    try:
        q0 = core.out.q.copy()
        tau = np.zeros(7)
        tau[joint] = torque_nm
        steps = 5
        for _ in range(steps):
            core.step(tau)
        ddq = core.out.dq / (steps * core.params.dt_s)
        geared, rigid = RobotModel(joints=ARMATURE_ONLY), RobotModel(joints=RIGID)
        expected = np.linalg.solve(_symmetric(pin.crba(geared.model, geared.data, q0)), tau)
        without = np.linalg.solve(_symmetric(pin.crba(rigid.model, rigid.data, q0)), tau)
        assert np.linalg.norm(ddq - expected) < 0.03 * np.linalg.norm(expected), (ddq, expected)
        assert np.linalg.norm(ddq - without) > 0.2 * np.linalg.norm(without), (ddq, without)
    finally:
        core.close()


def test_coulomb_friction_holds_a_joint_under_less_torque_than_it_and_lets_it_go_above():
    """A1 turns about the vertical: no gravity on it, only the step torque against its friction."""
    jd = JointDynamics()
    fc = jd.coulomb_nm[0]
    moved = {}
    for share in (0.5, 2.0):
        core = _sim(jd)
        try:
            q0 = core.out.q.copy()
            tau = np.zeros(7)
            tau[0] = share * fc
            for _ in range(500):
                core.step(tau)
            moved[share] = abs(core.out.q[0] - q0[0])
        finally:
            core.close()
    creep_rad = 0.5 * jd.coulomb_velocity_rad_s * np.arctanh(0.5)  # 0.5 s at the tanh law's creeping speed
    assert moved[0.5] < 1.5 * creep_rad + 1e-5, moved
    # above Fc it accelerates at about (tau - Fc) / (M_11 + Ia_1): ~0.18 rad/s^2, 22 mrad in 0.5 s
    assert moved[2.0] > 10e-3, moved
    assert moved[2.0] > 20 * moved[0.5], moved


def test_rigid_joints_take_the_motor_torques_as_they_are():
    core = _sim(RIGID)
    try:
        assert core.robot.joints.is_rigid
        q0 = core.out.q.copy()
        tau = np.linspace(-1.0, 1.0, 7)
        core.step(tau)
        rigid = RobotModel(joints=RIGID)
        expected = np.linalg.solve(_symmetric(pin.crba(rigid.model, rigid.data, q0)), tau)
        np.testing.assert_allclose(core.out.dq / core.params.dt_s, expected, rtol=1e-3, atol=1e-3)
    finally:
        core.close()


# -- configuration ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("table, match", [
    ({"armature_kg_m2": [0.1] * 6}, r"\[joints\] armature_kg_m2 must be a list of 7 finite numbers"),
    ({"coulomb_nm": [-0.1] + [0.1] * 6}, r"\[joints\] coulomb_nm must be a number in \[0.0, 20.0\]"),
    ({"coulomb_velocity_rad_s": 0.0}, r"coulomb_velocity_rad_s must be a number in \[0.0001, 1.0\]"),
    ({"stiction": 1.0}, r"\[joints\] unknown key\(s\) \['stiction'\]"),
])
def test_bad_joint_figures_name_the_key_and_the_valid_range(table, match):
    with pytest.raises(ConfigError, match=match):
        JointDynamics.from_table(table)


def test_the_joints_table_and_its_environment_overrides_reach_the_figures(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text("[joints]\ncoulomb_velocity_rad_s = 0.01\n")
    jd = joint_dynamics_from_config(path, env={"LAMPS__JOINTS__ARMATURE_KG_M2": "[0, 0, 0, 0, 0, 0, 0]"})
    assert jd.coulomb_velocity_rad_s == 0.01 and not any(jd.armature_kg_m2)
    assert jd.coulomb_nm == COULOMB_NM
    assert joint_dynamics_from_config(None, env={}) == JointDynamics()


def test_sim_joint_damping_points_to_the_joints_table():
    with pytest.raises(ConfigError, match=r"joint_damping_nm_s_rad: joint friction is set per joint in the \[joints\]"):
        SimParams.from_table({"joint_damping_nm_s_rad": 0.2})


def test_the_brake_stops_every_joint_together_over_its_stop_time_and_then_holds():
    """sim.robot.BRAKE_STOP_S: each joint's speed falls from what it was to zero along one ramp, all joints in
    proportion (the arm stays on its path, a path-maintaining stop), and then the arm stands; a brake that locked
    every joint within a step pressed a wiping pad into the board for that step (36 N at 10 N wiping)."""
    from sim.robot import BRAKE_STOP_S

    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}))
    try:
        push = np.array([4.0, -6.0, 3.0, 5.0, -2.0, 1.5, 1.0])  # the arm swings away from its start in free space
        for _ in range(150):
            sim.step(push)
        dq0 = sim.out.dq.copy()
        assert np.abs(dq0).max() > 0.3
        steps = int(round(BRAKE_STOP_S / sim.params.dt_s))
        speeds = []
        for _ in range(steps + 30):
            sim.step_braked()
            speeds.append(sim.out.dq.copy())
    finally:
        sim.close()
    for k in (steps // 4, steps // 2, 3 * steps // 4):  # on the ramp: the same share of every joint's speed
        want = dq0 * (1.0 - (k + 1) / steps)
        assert np.abs(speeds[k] - want).max() < 0.05 * np.abs(dq0).max(), (k, speeds[k], want)
    assert np.abs(speeds[steps + 5]).max() < 1e-3 and np.abs(speeds[-1]).max() < 1e-3  # then it stands
