"""The robot side damps the motion a late answer has not seen (robot/late_answer.py), with the real description."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from arm.robot_model import RobotModel
from robot.late_answer import RING, LateAnswerDamping

Q = np.array([0.1, 0.6, -0.2, -1.4, 0.3, 0.8, 0.1])
TAU = np.array([5.0, -20.0, 3.0, 10.0, -1.0, 2.0, 0.5])


@pytest.fixture(scope="module")
def model():
    return RobotModel()


def _late(model, rate=120.0) -> LateAnswerDamping:
    return LateAnswerDamping(model, rate, model.limits.tau_max)


def test_an_answer_on_time_is_applied_as_it_came(model):
    late = _late(model)
    for seq in range(5):
        late.record(seq, Q, np.full(7, 0.1 * seq))
    for seq in (4, 3, 2):  # the newest, one and two states old: what a prompt real-time answer is
        assert late.apply(TAU, seq) is TAU and late.damped_nm == 0.0
    assert late.late_by(2) == 2 and late.late_by(7) == -1 and late.late_by(-1) == -1


def test_a_late_answer_gets_the_motion_since_damped_on_each_joints_inertia(model):
    late = _late(model)
    dq = np.zeros((12, 7))
    dq[:, 5] = np.linspace(0.0, 1.1, 12)  # the wrist spinning up while the answer is on its way
    for seq in range(12):
        late.record(seq, Q + 0.001 * seq, dq[seq])
    tau = late.apply(TAU, 3)  # answering state 3 at state 11: 8 states late, 6 beyond the two on time
    data = model.model.createData()
    M = pin.crba(model.model, data, Q + 0.011)
    expected = TAU - 2 * 120.0 * np.diag(M) * (dq[11] - dq[5])
    np.testing.assert_allclose(tau, expected, rtol=1e-12)
    assert tau[5] < TAU[5] and np.allclose(np.delete(tau, 5), np.delete(TAU, 5))  # only the moving joint
    assert late.damped_nm == pytest.approx(abs(TAU[5] - tau[5]))
    assert np.diag(M)[5] > model.model.armature[5]  # the rotor inertia is in the diagonal, and the links' too


def test_the_damped_torques_stay_within_the_limits_and_an_unknown_state_is_left_alone(model):
    late = _late(model, rate=500.0)
    for seq in range(10):
        late.record(seq, Q, np.full(7, -3.0 * seq))
    tau = late.apply(model.limits.tau_max * 0.99, 0)
    assert np.all(np.abs(tau) <= model.limits.tau_max) and np.any(np.abs(tau) == model.limits.tau_max)
    for seq in range(10, 10 + RING):
        late.record(seq, Q, np.zeros(7))
    assert late.apply(TAU, 5) is TAU  # overwritten in the ring: not known, not guessed


def test_off_without_a_model_or_a_rate(model):
    for late in (LateAnswerDamping(None, 120.0, model.limits.tau_max), _late(model, rate=0.0)):
        for seq in range(10):
            late.record(seq, Q, np.full(7, seq))
        assert late.apply(TAU, 0) is TAU and not late.on
