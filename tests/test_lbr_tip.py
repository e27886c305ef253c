"""The stack's tip frame on our arm: lbr_description's chain (robot/lbr/stack_chain.py) against our description."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel
from robot.lbr.stack_chain import stack_chain, tip_in_link7
from robot.lbr.tip import stack_wrench_to_tcp, tip_jacobian, tip_pose
from sim.lbr_stack.stack import estimated_wrench


def test_stack_link7_and_tip_heights_at_zero():
    """At q = 0 the stack's link_7 is 1.271 m up and its link_ee 1.306 m (the flange); ours link 7 1.261 m."""
    stack, ee = stack_chain()
    data = stack.createData()
    pin.framesForwardKinematics(stack, data, np.zeros(7))
    assert np.allclose(data.oMi[7].translation, [0.0, 0.0, 1.271], atol=1e-12)
    assert np.allclose(data.oMf[ee].translation, [0.0, 0.0, 1.306], atol=1e-12)
    p, R = tip_in_link7()
    assert np.allclose(p, [0.0, 0.0, 0.045], atol=1e-9)
    assert np.allclose(R, np.eye(3), atol=1e-9)


def test_our_link7_plus_offset_is_the_stacks_link_ee_at_random_q():
    model = RobotModel()
    stack, ee = stack_chain()
    data = stack.createData()
    rng = np.random.default_rng(47)
    lim = model.limits
    for _ in range(50):
        q = rng.uniform(lim.q_min, lim.q_max)
        pin.framesForwardKinematics(stack, data, q)
        p, R = tip_pose(model, q)
        assert np.allclose(p, data.oMf[ee].translation, atol=1e-9)
        assert np.allclose(R, data.oMf[ee].rotation, atol=1e-9)
        # the tip's Jacobian (base axes, linear rows first) is the stack chain's at link_ee
        J_stack = pin.computeFrameJacobian(stack, data, q, ee, pin.LOCAL_WORLD_ALIGNED)
        assert np.allclose(tip_jacobian(model, q), J_stack, atol=1e-9)


def test_stack_wrench_at_its_tip_comes_back_as_the_pad_wrench():
    """A press on the pad, estimated at the stack's tip as the stand-in does, is brought back to the pad."""
    model = RobotModel()
    q = np.array([0.1, 0.6, -0.1, -1.4, 0.05, 0.9, 0.2])
    w_pad = np.array([1.0, -2.0, -10.0, 0.0, 0.0, 0.0])
    tau_ext = model.tcp_jacobian(q).T @ w_pad
    _, R = tip_pose(model, q)
    w_tip = estimated_wrench(tip_jacobian(model, q), tau_ext, R, 0.0, 0.0, 0.0, threshold_in_tip=False)
    assert np.allclose(stack_wrench_to_tcp(model, q, w_tip, 0.0, 0.0), w_pad, atol=1e-6)
