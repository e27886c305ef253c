"""Rotations and poses as plain numpy functions, named ``target_from_source``.

Quaternions are scalar first (``wxyz``) everywhere in LAMPS; PyBullet's
scalar-last order appears only in :func:`xyzw_from_wxyz` /
:func:`wxyz_from_xyzw`, used at the edge of ``sim/``. The rotation matrix /
quaternion conversions live in :mod:`lampskit.core.rotations` (the learner
needs them without the contract) and are part of this module's interface.
"""

from __future__ import annotations

import numpy as np

from lampskit.core.rotations import matrix_from_quat_wxyz, quat_wxyz_from_matrix

from .messages import Pose

__all__ = ["matrix_from_quat_wxyz", "quat_wxyz_from_matrix", "xyzw_from_wxyz", "wxyz_from_xyzw", "transform",
           "pose_from_transform", "transform_from_pose", "tool_rotation_on_board"]


def xyzw_from_wxyz(q: np.ndarray) -> tuple[float, float, float, float]:
    """PyBullet's scalar-last order from ours."""
    return (float(q[1]), float(q[2]), float(q[3]), float(q[0]))


def wxyz_from_xyzw(q) -> np.ndarray:
    """Our scalar-first order from PyBullet's."""
    return np.array([q[3], q[0], q[1], q[2]], float)


def transform(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(4, 4) homogeneous transform from rotation (3, 3) and translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def pose_from_transform(T: np.ndarray) -> Pose:
    """The wire :class:`~interfaces.messages.Pose` of a (4, 4) transform."""
    return Pose(position_m=[float(v) for v in T[:3, 3]], quat_wxyz=[float(v) for v in quat_wxyz_from_matrix(T[:3, :3])])


def transform_from_pose(pose: Pose) -> np.ndarray:
    """(4, 4) transform of a wire :class:`~interfaces.messages.Pose`."""
    return transform(matrix_from_quat_wxyz(np.array(pose.quat_wxyz)), np.array(pose.position_m))


def tool_rotation_on_board(R_board_to_world: np.ndarray) -> np.ndarray:
    """(3, 3) eraser orientation flat on a board: tool z into the board, the pad's long side along board x.

    The one convention the sim (start pose, reachability check) and the
    controller (wiping orientation) share. ``R_board_to_world`` (3, 3):
    board axes in the world (x along the width, y up the height, z out).
    """
    R = np.asarray(R_board_to_world, float)
    return np.column_stack([R[:, 0], -R[:, 1], -R[:, 2]])
