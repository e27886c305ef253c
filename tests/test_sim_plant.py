"""The simulated arm as a setting (``[sim.plant]``): each setting changes the arm PyBullet simulates and never the
controller's model; the identified profile loads; a bad setting is refused naming its key and range; the robot's
gravity compensation both ways."""

from __future__ import annotations

import dataclasses
import re
import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb
import pytest

from arm.description import URDF_PATH
from arm.joint_dynamics import JointDynamics, joint_dynamics_from_config
from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from runtime.config import declared_bounds, load_config
from sim.core import SimCore
from sim.params import SimParams
from sim.plant import LINK_NAMES, tool_gravity_torque
from sim.plant_params import PROFILES, STUERZ_2017_LINK_MASS_KG, PlantParams
from sim.world import GRAVITY_M_S2

from .conftest import REPO

NO_FRICTION = {"viscous_nm_s_rad": [0.0] * 7, "coulomb_nm": [0.0] * 7}


def _core(plant: dict | None = None, **sim) -> SimCore:
    return SimCore(SimParams.from_table({"camera": {"enabled": False}, **sim, **({"plant": plant} if plant else {})}))


def _dynamics(core: SimCore) -> tuple[np.ndarray, np.ndarray]:
    """PyBullet's mass matrix (7, 7) and gravity torques (7,) of the simulated arm at its start pose."""
    q = core.q_start.tolist()
    M = np.array(pb.calculateMassMatrix(core.world.robot, q, physicsClientId=core.client))
    return M, core.robot.gravity()


def _described_masses() -> np.ndarray:
    root = ET.parse(URDF_PATH).getroot()
    links = {el.get("name"): el for el in root.iter("link")}
    return np.array([float(links[n].find("inertial/mass").get("value")) for n in LINK_NAMES])


@pytest.fixture(scope="module")
def nominal():
    core = _core()
    yield _dynamics(core)
    core.close()


# ------------------------------------------------------------------------------------------------ declared settings
CASES = declared_bounds(PlantParams)


@pytest.mark.parametrize("name, kind, lo, hi", CASES, ids=[c[0] for c in CASES])
def test_a_declared_plant_setting_holds_its_default_and_refuses_values_past_either_end(name, kind, lo, hi):
    default = {f.name: f for f in dataclasses.fields(PlantParams)}[name].default
    assert lo <= default <= hi
    for bad in ((hi + 1 if kind is int else hi + max(abs(hi), 1.0) * 0.5),
                (lo - 1 if kind is int else lo - max(abs(lo), 1.0) * 0.5)):
        with pytest.raises(ConfigError, match=rf"\[sim.plant\] {name} must be .*\[{lo}, {hi}\], got {bad!r}"):
            PlantParams(**{name: bad})


@pytest.mark.parametrize("table, match", [
    ({"mass_scale": [1.0] * 6}, r"\[sim.plant\] mass_scale must be 7 numbers each in \[0.2, 3.0\], got \[1.0,"),
    ({"mass_scale": [1.0] * 6 + [4.0]}, r"\[sim.plant\] mass_scale must be 7 numbers each in \[0.2, 3.0\]"),
    ({"inertia_scale": 0.1}, r"\[sim.plant\] inertia_scale must be 7 numbers each in \[0.2, 3.0\]"),
    ({"com_offset_m": [[0, 0, 0]] * 6}, r"\[sim.plant\] com_offset_m must be 7 rows"),
    ({"com_offset_m": [[0, 0, 0.2]] * 7}, r"\[sim.plant\] com_offset_m must be 3 numbers each in \[-0.1, 0.1\]"),
    ({"tool_com_m": [0, 0, 0.5]}, r"\[sim.plant\] tool_com_m must be 3 numbers each in \[-0.3, 0.3\]"),
    ({"load_mass_kg": -1.0}, r"\[sim.plant\] load_mass_kg must be a number in \[0.0, 10.0\]"),
    ({"coulomb_nm": [30.0] * 7}, r"\[sim.plant\] coulomb_nm must be 7 numbers each in \[0.0, 20.0\]"),
    ({"torque_noise_nm": [-1.0] * 7}, r"\[sim.plant\] torque_noise_nm must be 7 numbers each in \[0.0, 20.0\]"),
    ({"profile": "iiwa7"}, r"\[sim.plant\] profile must be one of \['', 'stuerz2017'\]"),
    ({"mas_scale": 1.0}, r"\[sim.plant\] unknown key\(s\) \['mas_scale'\]"),
])
def test_a_bad_plant_setting_is_refused_at_start_up_naming_the_key_and_range(table, match):
    with pytest.raises(ConfigError, match=match):
        SimParams.from_table({"plant": table})


def test_the_default_plant_is_the_description():
    p = PlantParams()
    assert p.body_is_described and p.load_is_true and p.measurement_is_exact
    assert SimParams.from_table({}).plant == p


# ------------------------------------------------------------------------------ the simulated arm, not the controller
BODY_SETTINGS = {
    "mass_scale": {"mass_scale": [1.0, 1.3, 1.0, 1.3, 1.0, 1.0, 1.0]},
    "inertia_scale": {"inertia_scale": 1.5},
    "com_offset_m": {"com_offset_m": [[0, 0, 0], [0.0, 0.02, 0.0], [0, 0, 0], [0.0, 0.0, 0.02], [0, 0, 0],
                                      [0, 0, 0], [0, 0, 0]]},
    "tool_mass_kg": {"tool_mass_kg": 1.0},
    "tool_com_m": {"tool_mass_kg": 1.0, "tool_com_m": [0.05, 0.0, 0.03]},
    "profile": {"profile": "stuerz2017"},
    "random_mass_error": {"random_mass_error": 0.3, "seed": 4},
    "random_com_error_m": {"random_com_error_m": 0.02, "seed": 4},
}


@pytest.mark.parametrize("name", list(BODY_SETTINGS))
def test_each_body_setting_changes_the_simulated_arm_and_not_the_controllers_model(name, nominal, tmp_path):
    plant = BODY_SETTINGS[name]
    core = _core(plant)
    try:
        M, g = _dynamics(core)
        q = core.q_start
    finally:
        core.close()
    M0, g0 = nominal
    assert np.abs(M - M0).max() > 1e-4 or np.abs(g - g0).max() > 1e-3, name
    # the controller's model, built from the same configuration as `lamps controller` builds it
    toml = tmp_path / "cell.toml"
    toml.write_text("[sim.plant]\n" + "".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in plant.items()))
    assert "plant" in load_config(toml).table("sim")
    model = RobotModel(joints=joint_dynamics_from_config(toml))
    described = RobotModel()
    assert [i.mass for i in model.model.inertias] == [i.mass for i in described.model.inertias]
    np.testing.assert_array_equal(model.gravity(q), described.gravity(q))
    assert model.joints == JointDynamics()


def test_the_simulated_drives_take_the_plants_friction_and_armature_and_the_controller_keeps_its_own(tmp_path):
    own = {"armature_kg_m2": [0.1] * 7, "viscous_nm_s_rad": [2.0] * 7, "coulomb_nm": [1.0] * 7}
    toml = tmp_path / "cell.toml"
    toml.write_text("[sim.plant]\n" + "".join(f"{k} = {v!r}\n" for k, v in own.items()))
    assert joint_dynamics_from_config(toml) == JointDynamics()  # what the controller loads
    runs = {}
    for label, plant in (("own", own), ("shared", None)):
        core = _core(plant, gravity_compensated=True)
        try:
            assert core.robot.joints.armature_kg_m2 == (tuple(own["armature_kg_m2"]) if plant else
                                                        JointDynamics().armature_kg_m2)
            for _ in range(100):  # a push on A1 and A4 from rest: friction and rotor inertia slow it
                core.step(np.array([5.0, 0, 0, 3.0, 0, 0, 0]))
            runs[label] = core.out.dq.copy()
        finally:
            core.close()
    assert abs(runs["own"][0]) < 0.5 * abs(runs["shared"][0])
    assert abs(runs["own"][3]) < 0.75 * abs(runs["shared"][3])


def test_no_controller_or_robot_side_module_reads_the_plant():
    """The plant reaches the controller only through the robot's states: nothing outside sim/ imports it or
    reads the table (tests, the bench and the sim itself may)."""
    pattern = re.compile(r"sim\.plant|sim\.params|plant_params|[\"']plant[\"']|PLANT__")
    offenders = []
    for folder in ("controller", "robot", "interfaces", "runtime", "arm", "perception", "lampskit"):
        for path in (REPO / folder).rglob("*.py"):
            if pattern.search(path.read_text()):
                offenders.append(str(path.relative_to(REPO)))
    assert not offenders, offenders


# ---------------------------------------------------------------------------------------------- the identified profile
def test_the_identified_profile_loads_with_the_published_link_masses():
    core = _core({"profile": "stuerz2017"})
    try:
        masses = [pb.getDynamicsInfo(core.world.robot, j, physicsClientId=core.client)[0] for j in core.world.joints]
        described = _described_masses()
        inertia = [pb.getDynamicsInfo(core.world.robot, j, physicsClientId=core.client)[2] for j in core.world.joints]
    finally:
        core.close()
    np.testing.assert_allclose(masses, STUERZ_2017_LINK_MASS_KG, rtol=1e-12)
    assert PROFILES["stuerz2017"] == STUERZ_2017_LINK_MASS_KG and len(LINK_NAMES) == 7
    # the inertia follows the mass (the described shape): link 7 at 0.354 / 1.2 of its described inertia
    np.testing.assert_allclose(inertia[6][0], 0.001 * masses[6] / described[6], rtol=1e-9)


def test_random_link_errors_stay_within_their_bound_and_follow_the_seed():
    from sim.plant import link_changes

    described = _described_masses()
    a = link_changes(PlantParams(random_mass_error=0.3, random_com_error_m=0.02, seed=1), described)
    b = link_changes(PlantParams(random_mass_error=0.3, random_com_error_m=0.02, seed=1), described)
    c = link_changes(PlantParams(random_mass_error=0.3, random_com_error_m=0.02, seed=2), described)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.allclose(a[0], c[0])
    assert np.all(np.abs(a[0] - 1) <= 0.3) and np.all(np.abs(a[1] - 1) <= 0.3)
    lengths = np.linalg.norm(a[2], axis=1)
    assert lengths.max() <= 0.02 and lengths.max() > 0.002


# -------------------------------------------------------------------------------------------------- the tool's weight
def test_the_tool_load_is_in_the_simulated_arms_gravity_as_a_point_mass_on_the_flange(nominal):
    core = _core({"tool_mass_kg": 0.5, "tool_com_m": [0.03, 0.02, 0.03]})
    try:
        r = core.robot
        expected = tool_gravity_torque(r.c, r.w.robot, r.w.tcp_link, core.q_start.tolist(), 0.5,
                                       np.array([0.03, 0.02, 0.03]), r._zeros, GRAVITY_M_S2)
        np.testing.assert_allclose(r.gravity() - nominal[1], expected, atol=1e-9)
    finally:
        core.close()


# ------------------------------------------------------------------------------------- gravity compensation both ways
def _sag_m(plant: dict, gravity_compensated: bool, command=None, steps: int = 300) -> float:
    """How far [m] the pad moves in ``steps`` ms from rest under ``command(core)`` (default: zero torques)."""
    core = _core({**NO_FRICTION, **plant}, gravity_compensated=gravity_compensated)
    try:
        p0 = core.out.tcp_p.copy()
        for _ in range(steps):
            core.step(np.zeros(7) if command is None else command(core))
        return float(np.linalg.norm(core.out.tcp_p - p0))
    finally:
        core.close()


def test_compensated_the_robot_holds_its_true_weight_and_the_tool_by_its_load_data():
    true_tool = PlantParams(tool_mass_kg=0.8, tool_com_m=[0.0, 0.0, 0.05]).true_tool()
    right = {"tool_mass_kg": 0.8, "tool_com_m": [0.0, 0.0, 0.05], "load_mass_kg": true_tool[0],
             "load_com_m": list(true_tool[1])}
    assert _sag_m({"mass_scale": 1.3, "inertia_scale": 1.3, **right}, True) < 1e-4  # its own true model
    assert _sag_m({"tool_mass_kg": 0.8, "tool_com_m": [0.0, 0.0, 0.05]}, True) > 5e-3  # load data: the eraser only


def test_uncompensated_nothing_is_added_and_the_controllers_nominal_gravity_misses_a_heavier_arm():
    model = RobotModel()
    nominal = lambda core: model.gravity(core.out.q)  # noqa: E731  what a controller with the description adds
    assert _sag_m({}, False) > 0.05  # nothing compensated: the arm falls
    assert _sag_m({}, False, nominal) < 1e-3  # the description's gravity holds the described arm
    assert _sag_m({"mass_scale": 1.3, "inertia_scale": 1.3}, False, nominal) > 5e-3  # but not a heavier one


# ---------------------------------------------------------------------------------------------- what the sensors say
def test_the_measured_state_is_delayed_by_whole_periods_and_its_torques_biased_and_noisy():
    bias, noise = [0.5, -1.0, 0, 0, 0, 0, 2.0], [0.2, 0.2, 0, 0, 0, 0, 0.1]
    core = _core({"state_delay_periods": 3, "torque_bias_nm": bias, "torque_noise_nm": noise}, gravity_compensated=True)
    try:
        true_q, meas_q = [], []
        for _ in range(600):
            core.step(np.array([2.0, 0, 0, 0, 0, 0, 0]))
            true_q.append(core.out.q.copy())
            meas_q.append(core.measured[0].copy())
    finally:
        core.close()
    np.testing.assert_array_equal(meas_q[10], true_q[7])
    np.testing.assert_array_equal(meas_q[599], true_q[596])
    assert not np.array_equal(meas_q[599], true_q[599])
    core = _core({"torque_bias_nm": bias, "torque_noise_nm": noise}, gravity_compensated=True)
    try:
        diffs = []
        for _ in range(2000):
            core.step(np.zeros(7))
            diffs.append(core.measured[2] - core.out.tau)
    finally:
        core.close()
    d = np.array(diffs)
    np.testing.assert_allclose(d.mean(axis=0), bias, atol=0.02)
    np.testing.assert_allclose(d.std(axis=0), noise, atol=0.02)


def test_an_exact_plant_reports_the_simulated_state_itself():
    core = _core()
    try:
        core.step(np.zeros(7))
        q, dq, tau, wrench = core.measured
        assert q is core.out.q and tau is core.out.tau and wrench is core.out.wrench
    finally:
        core.close()


# ------------------------------------------------------------------------------------------- what the pad feels
def _wipe_on_the_board(plant: dict, steps: int = 1500) -> tuple[list, list]:
    """Press the pad on the default board with 10 N and drag it along the board's x with 8 N (the sim's own gravity
    compensated, a J^T force law with damping); per step in contact: (in-plane velocity (2,) [m/s], the reported
    in-plane force (2,) [N]) and the residual of the arm's equation (7,) [Nm] with the reported wrench."""
    core = _core(plant)
    model = RobotModel()
    try:
        r, board = core.robot, core.board
        n, Rb = board.normal_world, board.R
        ia = np.asarray(core.joints.armature_kg_m2)
        slides, residuals = [], []
        for _ in range(steps):
            o = core.out
            J = model.tcp_jacobian(o.q)
            touching = o.normal_force_n > 2.0
            force = -10.0 * n + (8.0 * Rb[:, 0] if touching else 0.0)
            twist = J @ o.dq
            damp = np.concatenate([40.0 * twist[:3] - 40.0 * (twist[:3] @ Rb[:, 0]) * Rb[:, 0] * touching,
                                   2.0 * twist[3:]])
            q0, dq0 = o.q.tolist(), o.dq.copy()
            M = np.array(pb.calculateMassMatrix(r.w.robot, q0, physicsClientId=core.client)) + np.diag(ia)
            h = np.array(pb.calculateInverseDynamics(r.w.robot, q0, o.dq.tolist(), [0.0] * 7,
                                                     physicsClientId=core.client))
            tau = r.gravity() + J.T @ np.concatenate([force, np.zeros(3)]) - J.T @ damp
            out = core.step(tau)
            if out.normal_force_n > 2.0 and touching:
                v, f = out.tcp_v @ Rb[:, :2], out.wrench[:3] @ Rb[:, :2]
                j = model.tcp_jacobian(np.array(q0))
                friction = core.joints.viscous_nm_s_rad * out.dq + core.joints.coulomb_nm * np.tanh(
                    out.dq / core.joints.coulomb_velocity_rad_s)
                residuals.append(M @ (out.dq - dq0) / 1e-3 + h + friction - tau - j.T @ out.wrench)
                slides.append((v, f))
        return slides, residuals
    finally:
        core.close()


@pytest.mark.parametrize("tool_kg", [0.0, 1.4])
def test_the_contact_wrench_is_what_the_arm_felt_and_friction_opposes_the_slide_with_a_heavy_tool_too(tool_kg):
    """With a 1.4 kg tool merged into the eraser link PyBullet reports the contact points' friction along the pad's
    slide; the sim's wrench comes from the arm's own motion, so it opposes the slide and explains the joint
    torques (the controller's disturbance watch sees what a force sensor would)."""
    slides, residuals = _wipe_on_the_board({"tool_mass_kg": tool_kg, "tool_com_m": [0.0, 0.0, 0.03]})
    sliding = [(v, f) for v, f in slides if np.linalg.norm(v) > 0.01]
    assert len(sliding) > 200, len(sliding)
    cosines = [float(v @ f / (np.linalg.norm(v) * np.linalg.norm(f))) for v, f in sliding]
    assert np.median(cosines) < -0.9 and max(cosines) < 0.0, (np.median(cosines), max(cosines))
    # the joint torques the wrench leaves unexplained (Coulomb friction flips near rest: the 95th percentile);
    # with the contact points' friction taken as reported, 5.7 Nm at A1 and 4.4 Nm at A3 with the tool
    p95 = np.percentile(np.abs(np.array(residuals)), 95, axis=0)
    assert p95.max() < 0.2, p95
