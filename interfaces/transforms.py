"""Rotations and poses as plain numpy functions, named ``target_from_source``.

Quaternions are scalar first (``wxyz``) everywhere in LAMPS; PyBullet's
scalar-last order appears only in :func:`xyzw_from_wxyz` /
:func:`wxyz_from_xyzw`, used at the edge of ``sim/``.
"""

from __future__ import annotations

import numpy as np

from .messages import Pose


def matrix_from_quat_wxyz(q: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of the unit quaternion ``q`` (4,) = (w, x, y, z)."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def quat_wxyz_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) = (w, x, y, z) of the rotation matrix ``R`` (3, 3), with w >= 0.

    Shepperd's method: divide by the largest of the four candidate diagonals,
    so it is accurate for every rotation, including half turns.
    """
    R = np.asarray(R, float)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


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
