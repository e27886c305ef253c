"""The stack's own kinematic chain of the iiwa 14 (lbr_description), as numbers, and its tip on our arm.

lbr_fri_ros2_stack's force-torque estimate is at ``<robot>_link_ee``
(``estimated_ft_sensor.chain_tip``: lbr_description/ros2_control/
lbr_system_config.yaml:25-26, rolling 218d723). Where that frame sits is
the stack's description, not ours: lbr_description/urdf/iiwa14/
iiwa14_description.xacro (rolling 218d723) puts the joints A1..A7 at the
origins and axes of :data:`STACK_JOINTS` (every rpy 0) and ``link_ee``
0.035 m above ``link_7`` (:data:`STACK_EE_IN_LINK7_M`); humble cca24ae has
the same numbers (``joint_ee`` at :287-291). At q = 0 its link_7 is 1.271 m
above link_0, ours (``iiwa_link_7``, arm/description/
iiwa14_eraser.urdf) 1.261 m: the two descriptions put link 7 at different
points of the same arm, and the tip is the flange (1.306 m, KUKA's data
sheet). :func:`tip_in_link7` derives the tip's pose in our link 7 from both
descriptions; tests/test_lbr_tip.py checks it at random joint positions.
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin

from arm.robot_model import URDF_PATH

#: (origin xyz [m] in the parent link, axis) of the stack's joints A1..A7, rpy all 0:
#: iiwa14_description.xacro (rolling 218d723) :52,55 / :86,89 / :120,123 / :154,157 / :188,191 / :222,225 /
#: :256,259.
STACK_JOINTS: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (
    ((0.0, 0.0, 0.1475), (0.0, 0.0, 1.0)),
    ((0.0, -0.01, 0.2125), (0.0, 1.0, 0.0)),
    ((0.0, 0.01, 0.228), (0.0, 0.0, 1.0)),
    ((0.0, 0.0105, 0.192), (0.0, -1.0, 0.0)),
    ((0.0, -0.0105, 0.2075), (0.0, 0.0, 1.0)),
    ((0.0, -0.0707, 0.1925), (0.0, 1.0, 0.0)),
    ((0.0, 0.0707, 0.091), (0.0, 0.0, 1.0)),
)
#: ``<robot>_joint_ee``: link_ee in link_7, xyz [m], rpy 0 (iiwa14_description.xacro:288-292, rolling 218d723).
STACK_EE_IN_LINK7_M = (0.0, 0.0, 0.035)
#: Our link 7 (arm/description/iiwa14_eraser.urdf).
LINK7_FRAME = "iiwa_link_7"
STACK_EE_FRAME = "lbr_link_ee"


def stack_chain() -> tuple[pin.Model, int]:
    """(the stack's chain link_0 .. link_7 as a Pinocchio model, the frame id of its link_ee); link_0 is the base."""
    model = pin.Model()
    parent = 0
    for i, (xyz, axis) in enumerate(STACK_JOINTS):
        parent = model.addJoint(parent, pin.JointModelRevoluteUnaligned(np.array(axis, float)),
                                pin.SE3(np.eye(3), np.array(xyz, float)), f"A{i + 1}")
        model.appendBodyToJoint(parent, pin.Inertia.Identity(), pin.SE3.Identity())
    ee = model.addFrame(pin.Frame(STACK_EE_FRAME, parent, 0, pin.SE3(np.eye(3), np.array(STACK_EE_IN_LINK7_M)),
                                  pin.FrameType.OP_FRAME))
    return model, ee


@functools.cache
def tip_in_link7() -> tuple[np.ndarray, np.ndarray]:
    """``(p (3,) [m], R (3, 3))``: the stack's link_ee in our ``iiwa_link_7`` frame (the same at every q, since the
    chains are the same arm; derived at q = 0 from the stack's chain and our description)."""
    ours = pin.buildModelFromUrdf(str(URDF_PATH))
    data = ours.createData()
    q0 = np.zeros(ours.nq)
    pin.framesForwardKinematics(ours, data, q0)
    link7 = data.oMf[ours.getFrameId(LINK7_FRAME)]
    stack, ee = stack_chain()
    sdata = stack.createData()
    pin.framesForwardKinematics(stack, sdata, np.zeros(stack.nq))
    rel = link7.inverse() * sdata.oMf[ee]
    return rel.translation.copy(), rel.rotation.copy()
