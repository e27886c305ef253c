"""The controller learns the arm it drives: the flange load's regressor against Pinocchio, the bounded
correction observer, the settings' checks, then the whole skill in process (PyBullet plant that is not the
controller's model, Pinocchio controller): an unknown tool estimated before the first wipe, tracking in contact on
the +15 % links / +0.5 kg tool plant in both robot gravity modes."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from arm.description import ERASER_LINK
from arm.robot_model import RobotModel
from controller.control.model_correction import MODEL_MISMATCH, CorrectionParams, ModelCorrection
from controller.core import ControllerCore
from controller.executor_types import BoardPose
from controller.params import ControllerParams
from controller.tool_estimate import GRAVITY_M_S2, ToolEstimate, tool_regressor_into
from controller.trace import PHASE_CODES, TRACE_COLUMNS
from interfaces.errors import ConfigError
from interfaces.messages import ControllerStatus, Phase
from lampskit.core.planner_types import Stain

from .core_ticks import tick

#: The learning controller (opt-in: [controller.model] enabled, with the identification roll).
LEARNING = {"enabled": True, "identify_s": 2.0}

DT = 0.001
#: The plant's unknown tool: 0.8 kg at (1, -2, 5) cm of the flange frame (with the description's eraser).
TOOL = {"tool_mass_kg": 0.8, "tool_com_m": [0.01, -0.02, 0.05]}
PLUS_15 = {"mass_scale": 1.15, "inertia_scale": 1.15, "tool_mass_kg": 0.5}


def test_the_load_regressor_is_the_gravity_torque_pinocchio_gives_a_model_with_the_mass_added():
    rm = RobotModel()
    m, d = rm.model, rm.data
    est = ToolEstimate.for_model(rm, torque_noise_nm=1e-6)  # exact torques: five poses tell every direction
    mass, com_flange = 0.8, np.array([0.01, -0.02, 0.05])
    flange = m.frames[m.getFrameId(ERASER_LINK)]
    heavier = m.copy()
    heavier.inertias[flange.parentJoint] += pin.Inertia(mass, flange.placement.act(com_flange), np.zeros((3, 3)))
    Y = np.zeros((7, 4))
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(m.lowerPositionLimit, m.upperPositionLimit)
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        J = pin.getFrameJacobian(m, d, rm.tcp_id, pin.LOCAL_WORLD_ALIGNED)
        tool_regressor_into(J, d.oMf[rm.tcp_id].rotation, GRAVITY_M_S2, Y)
        expected = pin.computeGeneralizedGravity(heavier, heavier.createData(), q) - \
            pin.computeGeneralizedGravity(m, m.createData(), q)
        theta = np.r_[mass, mass * (com_flange - est.pad_in_flange_m)]
        np.testing.assert_allclose(Y @ theta, expected, atol=1e-10)
        est.add(J, d.oMf[rm.tcp_id].rotation, expected)
    est.n = max(est.n, 20)  # five exact poses; the count only guards against fitting noise from too few
    assert est.solve()
    assert est.mass_kg == pytest.approx(mass, abs=1e-9)
    np.testing.assert_allclose(est.com_flange_m, com_flange, atol=1e-9)



def test_a_centre_of_mass_along_gravity_at_every_sample_is_not_made_up_the_rest_is_fitted():
    """A wall board's approach without the roll: the pad's y axis stays along gravity, the pad turns about the
    vertical only (tipped by a degree at most). The load's offset along y hardly moves a joint at any sample; with
    0.2 Nm of noise a plain least-squares fit puts it anywhere. The estimate keeps it at the pad centre and says so."""
    rm = RobotModel()
    m, d = rm.model, rm.data
    est = ToolEstimate.for_model(rm)
    mass, com_flange = 1.4, np.array([0.0, 0.03, 0.03])
    theta = np.r_[mass, mass * (com_flange - est.pad_in_flange_m)]
    rng = np.random.default_rng(5)
    Y = np.zeros((7, 4))
    for _ in range(400):
        q = rng.uniform(m.lowerPositionLimit, m.upperPositionLimit)
        pin.computeJointJacobians(m, d, q)
        J = pin.getFrameJacobian(m, d, rm.tcp_id, pin.LOCAL_WORLD_ALIGNED)
        yaw, tilt = rng.uniform(-0.6, 0.6), rng.uniform(-0.02, 0.02)  # turned about the vertical, tipped 1 degree
        x = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        y = np.array([0.0, 0.0, -1.0]) * np.cos(tilt) + np.cross(x, [0.0, 0.0, -1.0]) * np.sin(tilt)
        R = np.column_stack([x, y, np.cross(x, y)])
        tool_regressor_into(J, R, GRAVITY_M_S2, Y)
        est.add(J, R, Y @ theta + rng.normal(0.0, 0.2, 7))
    assert est.solve() and est.unobserved == 1
    assert est.mass_kg == pytest.approx(mass, rel=0.02)
    assert abs(est.com_flange_m[0] - com_flange[0]) < 0.005 and abs(est.com_flange_m[2] - com_flange[2]) < 0.005
    assert abs(est.com_flange_m[1] - est.pad_in_flange_m[1]) < 0.002, (est.com_flange_m, "along gravity: the prior")

def test_a_residual_that_is_the_links_model_error_does_not_hide_what_the_excitation_tells():
    """Links 30 % heavier than the model: the missing torque is mostly theirs (a residual of Nm, not noise). Every
    direction the poses excite is fitted (the flange load then takes the part of the links' error it can explain),
    judged at the sensor's noise; a threshold at the fit's residual kept two directions at the prior."""
    rm = RobotModel()
    m, d = rm.model, rm.data
    est = ToolEstimate.for_model(rm)
    heavier = m.copy()
    for i in range(1, m.njoints):
        heavier.inertias[i] = pin.Inertia(1.3 * m.inertias[i].mass, m.inertias[i].lever, 1.3 * m.inertias[i].inertia)
    rng = np.random.default_rng(7)
    for _ in range(400):
        q = rng.uniform(m.lowerPositionLimit, m.upperPositionLimit)
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        J = pin.getFrameJacobian(m, d, rm.tcp_id, pin.LOCAL_WORLD_ALIGNED)
        missing = pin.computeGeneralizedGravity(heavier, heavier.createData(), q) - \
            pin.computeGeneralizedGravity(m, m.createData(), q)
        est.add(J, d.oMf[rm.tcp_id].rotation, missing + rng.normal(0.0, 0.05, 7))
    assert est.solve()
    assert est.residual_rms_nm > 0.5, est.residual_rms_nm  # the links' error, not noise
    assert est.unobserved == 0
    np.testing.assert_allclose(est.theta, np.linalg.solve(est.A, est.b), rtol=1e-9, atol=1e-12)


def test_the_sensor_noise_must_be_positive():
    with pytest.raises(ValueError, match="torque_noise_nm"):
        ToolEstimate(np.zeros(3), torque_noise_nm=0.0)


def test_the_correction_follows_the_missing_torque_stays_within_its_bound_and_warns_there():
    tau_max = np.full(7, 100.0)
    corr = ModelCorrection(CorrectionParams(enabled=True, integral_s=0.1, bound_share=0.1, warn_s=0.2), tau_max)
    delta = np.array([3.0, -5.0, 0.0, 1.0, 0.0, 0.0, -0.5])  # what the model misses [Nm]
    for _ in range(2000):  # 2 s = 20 time constants
        corr.update(corr.c - delta, DT)  # the watch's residual once c counts as model: c - delta
        corr.c[:] = corr.z  # no load fitted: c = z
    np.testing.assert_allclose(corr.c, delta, atol=1e-6)
    assert not corr.warning
    delta[1] = -25.0  # beyond the bound (10 Nm): held there, named after warn_s
    for _ in range(1000):
        corr.update(corr.c - delta, DT)
        corr.c[:] = corr.z
    assert corr.z[1] == -10.0 and corr.warning.startswith(MODEL_MISMATCH) and "A2" in corr.warning


@pytest.mark.parametrize("key, value", [("integral_s", 0.0), ("bound_share", 0.9), ("identify_s", -1.0),
                                        ("enabled", "yes")])
def test_a_bad_model_setting_is_refused_naming_the_key(key, value):
    with pytest.raises(ConfigError, match=key):
        ControllerParams.from_table({"model": {key: value}})


def _stains(core: ControllerCore, sim) -> None:
    board = BoardPose.from_transform(sim.board.T_board_to_world, sim.board.size_m)
    core.executor.set_stains(board, [Stain(s.id, np.array(s.centre_m), s.size_m, kappa=bool(r <= 0.03))
                                     for s, r in zip(sim.dirt.stains, sim.dirt.remaining())])


def _run(skill, plant: dict, compensated: bool, until_first_wipe: bool, ticks: int = 90_000):
    """The skill against a SimCore on ``plant`` (the controller keeps the description); the stains are given once
    the identification roll has begun (a board known at once skips it). Returns (core, the flange load estimate at
    the first WIPE as (fitted, mass, com), in-contact wiping tracking RMS [m])."""
    from sim.core import SimCore
    from sim.params import SimParams

    core = ControllerCore(ControllerParams.from_table({"trace_ticks": ticks, "model": LEARNING}), skill)
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": compensated,
                                        "plant": plant}))
    applied, at_wipe = None, None
    try:
        for n in range(ticks):
            if n >= 100 and n % 100 == 0:
                _stains(core, sim)
            o = sim.out
            applied = tick(core, o.q, o.dq, o.wrench, compensated, DT, None, applied).copy()
            if at_wipe is None and core.executor.phase == Phase.WIPE:
                t = core.arm.tool
                at_wipe = (t.valid, t.mass_kg, t.com_flange_m.copy())
                if until_first_wipe:
                    break
            sim.step(applied)
            if core.executor.phase in (Phase.DONE, Phase.FAULT):
                break
    finally:
        sim.close()
    tr, c = core.trace.array(), {name: i for i, name in enumerate(TRACE_COLUMNS)}
    wiping = (tr[:, c["phase"]] == PHASE_CODES["WIPE"]) & (tr[:, c["contact"]] > 0.5)
    err = np.hypot(tr[wiping, c["ref_x"]] - tr[wiping, c["x"]], tr[wiping, c["ref_y"]] - tr[wiping, c["y"]])
    return core, at_wipe, float(np.sqrt(np.mean(err ** 2))) if err.size else float("nan")


@pytest.mark.slow
@pytest.mark.parametrize("compensated", [False, True], ids=["controller-gravity", "robot-gravity"])
def test_an_unknown_tool_is_estimated_before_the_first_wipe(learned_skill, compensated):
    """0.8 kg the description does not carry, 5 cm out and 2 cm off the flange axis: within 10 % and 1 cm when
    the first wipe starts (measured: 0.800 kg, (1.04, -1.96, 5.09) cm with the controller adding gravity)."""
    core, at_wipe, _ = _run(learned_skill, TOOL, compensated, until_first_wipe=True)
    assert at_wipe is not None, f"no wipe began: {core.executor.phase} {core.executor.reason}"
    fitted, mass, com = at_wipe
    assert fitted
    assert mass == pytest.approx(TOOL["tool_mass_kg"], rel=0.10)
    assert np.linalg.norm(com - TOOL["tool_com_m"]) < 0.01, com
    status = ControllerStatus(seq=1, stamp_ns=1, phase=core.executor.phase, arm=core.arm.estimate())
    assert status.arm.tool_fitted and status.arm.tool_mass_kg == mass and len(status.arm.correction_nm) == 7


@pytest.mark.slow
@pytest.mark.parametrize("compensated", [False, True], ids=["controller-gravity", "robot-gravity"])
def test_the_heavier_arm_with_an_unlisted_tool_is_tracked_within_3_5_mm_in_contact(learned_skill, compensated):
    """Link masses and inertias +15 %, 0.5 kg on the flange: the plain controller tracks 11.4 mm (controller
    gravity) and 4.1 mm (robot gravity) in process; with the correction 1.62 and 1.65 mm."""
    core, _, rms = _run(learned_skill, PLUS_15, compensated, until_first_wipe=False)
    assert core.executor.phase == Phase.DONE, core.executor.reason
    assert rms <= 3.5e-3, f"tracking RMS in contact {rms * 1e3:.2f} mm"
    assert not core.arm.correction.warning
