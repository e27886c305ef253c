"""Whether the arm, at its start pose, leaves the camera enough of the board's markers (pure maths, one FK).

Before perception has a board pose the controller holds the arm where it
stands (WAIT_PEERS: it cannot fly the pad towards a board it does not know),
so a start pose whose links hide the board's corner markers from the camera
is a cell that never starts: perception's first pose needs
:data:`MARKERS_NEEDED` markers (``perception/board.py``, ``_why_not``:
three while the board's size is not known), and on random board 636 the arm
hid two of the four ("only markers [1, 2] seen (need 3)", every frame) until
``lamps up``'s wall-time limit.

The arm is drawn as :mod:`arm.silhouette` draws it, four capsules along its
centre line, here from the start pose's joints themselves (the base column
under the shoulder, the shoulder, the elbow, the wrist centre, the pad), not
guessed from the pad pose. A marker counts as hidden when
:data:`HIDDEN_POINTS` of its five points (four corners and centre) are: the
capsules' radii carry a margin, and on the campaign's recorded cells a
marker with one or two of them covered was still found (boards 241 and 263,
marker 3) where two with four and five covered were not (board 636).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel
from arm.silhouette import hidden
from interfaces.board_markers import marker_corners_board

if TYPE_CHECKING:  # sim.board chooses its start pose with this module's count
    from .board import Board

#: Markers perception needs for its first board pose (``perception/board.py``, ``BoardTracker._why_not``: 3 while
#: the board's size is unknown, ``[perception.board] min_markers`` after).
MARKERS_NEEDED = 3
#: Markers perception needs to go on with a board it has found (``[perception.board] min_markers``, 2 by default): what
#: the arm must leave the camera while it wipes (:func:`sim.board.start_configuration`).
MARKERS_HELD = 2
#: Of a marker's five points (corners and centre), how many the arm must cover for the marker to count as hidden.
HIDDEN_POINTS = 3


def arm_line_from_joints(model: RobotModel, q: np.ndarray) -> np.ndarray:
    """(5, 3) [m, world] the arm's centre line at joints ``q`` (n,) [rad]: the mounting plane under the shoulder,
    the shoulder (A2's origin), the elbow (A4's), the wrist centre (A6's) and the pad (the tool frame)."""
    data = model.model.createData()
    pin.framesForwardKinematics(model.model, data, np.asarray(q, float))
    shoulder, elbow, wrist = (data.oMi[i].translation.copy() for i in (2, 4, 6))
    base = shoulder.copy()
    base[2] = 0.0
    return np.stack([base, shoulder, elbow, wrist, data.oMf[model.tcp_id].translation.copy()])


def markers_hidden_at_start(board: Board, q: np.ndarray, camera_m: np.ndarray, model: RobotModel) -> list[int]:
    """The ids of ``board``'s markers the arm at joints ``q`` (n,) [rad] hides from a camera at ``camera_m`` (3,)
    [m, world], sorted."""
    line = arm_line_from_joints(model, q)
    ids, points = [], []
    for marker_id, corners in marker_corners_board((float(board.size_m[0]), float(board.size_m[1]))).items():
        xy = np.vstack([corners, corners.mean(axis=0)])  # (5, 2) board frame
        points.append(board.world_from_board(xy))
        ids.append(marker_id)
    cover = hidden(np.vstack(points), np.asarray(camera_m, float), line)  # (4 * 5,)
    return sorted(i for i, c in zip(ids, cover.reshape(len(ids), -1), strict=True) if int(c.sum()) >= HIDDEN_POINTS)


def start_view_problem(board: Board, q: np.ndarray, camera_m: np.ndarray, model: RobotModel) -> str | None:
    """Why perception could not find ``board`` with the arm at its start pose ``q`` (n,) [rad] (None: it could):
    fewer than :data:`MARKERS_NEEDED` markers left in view of the camera at ``camera_m`` (3,) [m, world]."""
    gone = markers_hidden_at_start(board, q, camera_m, model)
    left = len(marker_corners_board((float(board.size_m[0]), float(board.size_m[1])))) - len(gone)
    if left >= MARKERS_NEEDED:
        return None
    return (f"the arm at its start pose hides markers {gone} from the camera: {left} left in view, perception "
            f"needs {MARKERS_NEEDED} for the board's first pose")
