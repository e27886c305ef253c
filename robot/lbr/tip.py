"""The stack's tip frame (``lbr_link_ee``) on our arm, and its wrench estimate brought to the pad.

lbr_description places ``<robot>_link_ee`` 0.035 m along its own link 7's z
axis (``urdf/iiwa14/iiwa14_description.xacro``:288-292, rolling 218d723),
which is 0.045 m above our ``iiwa_link_7`` (the flange): the offset is
derived from the stack's chain in :mod:`robot.lbr.stack_chain`. Its
``force_torque_broadcaster`` publishes the estimated wrench there, in the
tip's axes, with a soft deadband (each component below its threshold is
0, above it it loses the threshold: ``lbr_fri_ros2/include/lbr_fri_ros2/
ft_estimator.hpp``:26-28). :func:`stack_wrench_to_tcp` turns such a
wrench into what the controller uses: force and torque about the pad
centre, world (base) axes, the threshold given back to every non-zero
component (a zero one stays unknown within +-threshold).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel

from .stack_chain import LINK7_FRAME, tip_in_link7

#: The stack's tip (``lbr_link_ee``) in our link 7: position [m] and rotation.
TIP_OFFSET_M, TIP_ROTATION = tip_in_link7()


def tip_pose(model: RobotModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(p (3,) [m], R (3, 3))`` of ``lbr_link_ee`` in the base frame."""
    fid = model.model.getFrameId(LINK7_FRAME)
    pin.framesForwardKinematics(model.model, model.data, q)
    oMf = model.data.oMf[fid]
    return oMf.translation + oMf.rotation @ TIP_OFFSET_M, oMf.rotation @ TIP_ROTATION


def tip_jacobian(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """(6, 7) Jacobian of ``lbr_link_ee``, base axes, linear rows first (the point moves with the tip)."""
    fid = model.model.getFrameId(LINK7_FRAME)
    pin.computeJointJacobians(model.model, model.data, q)
    pin.updateFramePlacements(model.model, model.data)
    J = pin.getFrameJacobian(model.model, model.data, fid, pin.LOCAL_WORLD_ALIGNED).copy()
    r = model.data.oMf[fid].rotation @ TIP_OFFSET_M
    J[:3] -= np.cross(r, J[3:].T).T  # v_tip = v_7 + w x r = v_7 - r x w
    return J


def stack_wrench_to_tcp(model: RobotModel, q: np.ndarray, w_tip: np.ndarray, force_threshold_n: float,
                        torque_threshold_nm: float) -> np.ndarray:
    """(6,) force [N] and torque about the pad centre [Nm], base axes, from the stack's tip wrench ``w_tip``
    (6,) (tip axes, torque about the tip, soft-thresholded) at joint positions ``q`` (7,)."""
    th = np.array([force_threshold_n] * 3 + [torque_threshold_nm] * 3)
    w = np.where(w_tip != 0.0, w_tip + np.sign(w_tip) * th, 0.0)
    p_tip, R = tip_pose(model, q)
    p_tcp, _ = model.tcp_pose(q)
    f = R @ w[:3]
    m_tip = R @ w[3:]
    return np.concatenate([f, m_tip + np.cross(p_tip - p_tcp, f)])
