"""``lamps learn`` on the cell: lampskit's learner (:func:`lampskit.cli.learn_main`) given the described arm.

The learner itself knows no robot (``lampskit`` imports nothing of the cell): a robot recording is read with
the arm it is handed (:class:`~lampskit.learn.bags.ArmKinematics`). This module builds that arm from the robot
description (:mod:`arm.robot_model`: Pinocchio forward kinematics of the KUKA LBR iiwa 14 with the
eraser) and from the lbr stack's message definitions (:mod:`robot.lbr.msgs`).

Joint names accepted, joint 1 first:

- ``A1`` .. ``A7`` (lbr_fri_ros2_stack ``humble`` cca24ae,
  lbr_description/urdf/iiwa14/iiwa14_description.xacro:50, 84, 118, ...);
- ``<robot_name>_A1`` .. (``rolling`` 218d723, same file lines 51, 85, ..., 255; ``lbr`` by default);
- ``iiwa_joint_1`` .. (this project's description, :data:`arm.description.JOINT_NAMES`).
"""

from __future__ import annotations

import re

import numpy as np

from lampskit.learn.bags import LBR_STATE, ArmKinematics

_NAME = re.compile(r"^(?:(?:.+_)?A([1-7])|iiwa_joint_([1-7]))$")
JOINT_NAMES_TEXT = "A1..A7, <robot_name>_A1..A7 as the lbr stack names them, or iiwa_joint_1..7"


def iiwa_joint_index(name: str) -> int | None:
    """0-based joint number of one of the iiwa's joint names (see the module docstring), else None."""
    m = _NAME.match(name)
    return None if m is None else int(m.group(1) or m.group(2)) - 1


def learn_main(argv: list[str]) -> int:
    """``lamps learn``: :func:`lampskit.cli.learn_main` reading robot recordings with :func:`described_arm`."""
    from lampskit.cli import learn_main as learn

    return learn(argv, arm=described_arm)


def described_arm() -> ArmKinematics:
    """The arm of :mod:`arm.description`: Pinocchio FK to the flange, the eraser's pad as the tool."""
    import pinocchio as pin

    from arm.description import ERASER_LINK, TCP_FRAME
    from arm.robot_model import RobotModel
    from robot.lbr.msgs import LBR_STATE_MSG, LBR_STATE_MSG_FRI2

    model = RobotModel()
    flange = model.model.getFrameId(ERASER_LINK)  # the eraser link's frame is the flange (its mount is fixed)
    tcp = model.model.getFrameId(TCP_FRAME)
    pin.framesForwardKinematics(model.model, model.data, np.zeros(model.nq))
    offset = model.data.oMf[flange].actInv(model.data.oMf[tcp]).translation

    def flange_poses(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p, R = np.empty((len(q), 3)), np.empty((len(q), 3, 3))
        for k, qk in enumerate(np.asarray(q, float)):
            pin.framesForwardKinematics(model.model, model.data, qk)
            p[k], R[k] = model.data.oMf[flange].translation, model.data.oMf[flange].rotation
        return p, R

    tool_offset_m = (float(offset[0]), float(offset[1]), float(offset[2]))
    return ArmKinematics(n_joints=model.nq, joint_index=iiwa_joint_index, joint_names=JOINT_NAMES_TEXT,
                         flange_poses=flange_poses, tool_offset_m=tool_offset_m,
                         msg_layouts={LBR_STATE: (LBR_STATE_MSG, LBR_STATE_MSG_FRI2)})
