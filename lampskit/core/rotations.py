"""Rotation matrices and unit quaternions (scalar first, ``wxyz``), named ``target_from_source``.

The bottom of the project's frame maths: the learner reads demonstrations'
orientations with it, :mod:`interfaces.transforms` builds poses on it.
"""

from __future__ import annotations

import numpy as np


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
