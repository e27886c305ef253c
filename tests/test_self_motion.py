"""The self-motion bound on the nullspace posture (controller/control/limits.py ``self_motion_limit``): near the
wrist's singular pose (A6 near 0) a push in the task's nullspace turns A5 and A7 many times faster than A6, so the
clearance is scaled by the speed of the self-motion it drives and any self-motion above a share of the joints' speed
limits is braked, never the pad.

The cell: random board 9 with 6 stains (``lamps up --board random:9``), where the clearance held A6 off zero against
the rest posture's pull and, faded out by the wrist's speed, let that pull spin A5 to 0.89 of its speed limit.
"""

from __future__ import annotations

import numpy as np
import pytest

from arm.robot_model import RobotModel
from controller.control.impedance import Kinematics
from controller.control.limits import self_motion_limit

#: Near the wrist's singular pose (A6 = 0.15 rad): A5 and A7 turn about nearly one axis.
Q_WRIST = np.array([0.2, 0.7, -0.1, -1.3, 0.4, 0.15, 0.3])


def _arm(q: np.ndarray) -> tuple[Kinematics, np.ndarray]:
    model = RobotModel()
    kin = Kinematics(model)
    kin.update(q, np.zeros(7))
    return kin, model.limits.dq_max


def _null(kin: Kinematics, x: np.ndarray) -> np.ndarray:
    """The nullspace part of a joint velocity (dynamically consistent)."""
    return x - kin.M_inv @ kin.J.T @ kin.Lambda @ kin.J @ x


def test_a_push_on_a6_near_its_singular_pose_turns_a5_and_a7_many_times_faster():
    """Why the bound: the self-motion that a torque on A6 drives turns A5 and A7 by 10-20 rad per rad of A6."""
    kin, _ = _arm(Q_WRIST)
    push = np.zeros(7)
    push[5] = 1.0
    a = _null(kin, kin.M_inv @ push)
    assert abs(a[4]) > 10 * abs(a[5]) and abs(a[6]) > 10 * abs(a[5]), a
    assert np.linalg.norm(kin.J @ a) < 1e-4 * np.linalg.norm(a)


def test_the_clearance_holds_at_rest_and_fades_with_the_self_motion_it_drives():
    kin, dq_max = _arm(Q_WRIST)
    push = np.zeros(7)
    push[5] = 10.0
    a = _null(kin, kin.M_inv @ push)
    unit = a / np.max(np.abs(a) / dq_max)  # moving at s * unit: the fastest joint at share |s|
    for share, gain in ((0.0, 1.0), (0.1, 1.0), (0.15, 0.5), (0.2, 0.0), (0.5, 0.0), (-0.5, 1.0)):
        tau = push.copy()
        got = self_motion_limit(tau, share * unit, kin.M, kin.M_inv, kin.J, kin.Lambda, dq_max, 0.2, 0.0)
        assert got == pytest.approx(gain, abs=1e-6), share
        np.testing.assert_allclose(tau, gain * push, atol=1e-6, err_msg=str(share))


def test_a_fast_self_motion_is_braked_in_the_nullspace_only():
    kin, dq_max = _arm(Q_WRIST)
    rng = np.random.default_rng(3)
    task = kin.M_inv @ kin.J.T @ rng.normal(0, 1, 6)  # a motion of the pad (M-orthogonal to the nullspace)
    task *= 0.6 / np.max(np.abs(task) / dq_max)
    tau = np.zeros(7)
    self_motion_limit(tau, task, kin.M, kin.M_inv, kin.J, kin.Lambda, dq_max, 0.2, 50.0)
    np.testing.assert_allclose(tau, 0.0, atol=1e-6)  # the pad's motion alone: no brake, however fast
    v = _null(kin, rng.normal(0, 1, 7))
    for share, braked in ((0.15, False), (0.5, True)):
        dq = task + v * share / np.max(np.abs(v) / dq_max)
        tau = np.zeros(7)
        self_motion_limit(tau, dq, kin.M, kin.M_inv, kin.J, kin.Lambda, dq_max, 0.2, 50.0)
        if not braked:
            np.testing.assert_allclose(tau, 0.0, atol=1e-9)
            continue
        assert tau @ _null(kin, dq) < 0.0  # against the self-motion
        accel = kin.M_inv @ tau
        assert np.linalg.norm(kin.J @ accel) < 1e-4 * np.linalg.norm(accel)  # the pad is not braked


def test_bad_arguments_are_named():
    kin, dq_max = _arm(Q_WRIST)
    with pytest.raises(ValueError, match="J must have shape"):
        self_motion_limit(np.zeros(7), np.zeros(7), kin.M, kin.M_inv, kin.J[:5], kin.Lambda, dq_max, 0.2)
    with pytest.raises(ValueError, match="share > 0"):
        self_motion_limit(np.zeros(7), np.zeros(7), kin.M, kin.M_inv, kin.J, kin.Lambda, dq_max, 0.0)


@pytest.mark.slow
def test_random_board_9_wipes_with_every_joint_under_0_8_of_its_speed_limit(tmp_path):
    from .test_arm_clearance import run_random_board

    report, stdout, sim = run_random_board(tmp_path, 9, 6)
    assert report["outcome"] == "cleaned", (report["outcome"], report["faults"], stdout[-3000:])
    assert not {k: v for k, v in sim.items() if ("brake" in k or "yield" in k or "fault" in k) and v}, sim
    assert report["max_joint_speed_ratio"] < 0.8, report["max_joint_speed_ratio"]
