"""Where the ArUco markers sit on a whiteboard: the contract between the board (sim or real) and perception.

Four markers of OpenCV's ``DICT_4X4_50``, ids 0-3, one in each corner of
the board, printed upright when the board is seen from the front (its z
axis towards the viewer, its y axis up):

====  ===================
 id   corner
====  ===================
 0    bottom-left (origin)
 1    bottom-right
 2    top-right
 3    top-left
====  ===================

Each marker is a square of side :data:`MARKER_SIDE_M` (black border
included) whose outer corner is :data:`MARKER_INSET_M` from both board
edges.
"""

from __future__ import annotations

import numpy as np

ARUCO_DICTIONARY = "DICT_4X4_50"
MARKER_IDS: tuple[int, int, int, int] = (0, 1, 2, 3)
MARKER_SIDE_M = 0.06
MARKER_INSET_M = 0.01
#: Cells of one marker including its black border (4x4 bits + 1 border cell each side).
MARKER_CELLS = 6


def marker_origins_board(board_size_m: tuple[float, float]) -> dict[int, np.ndarray]:
    """Bottom-left corner (2,) [m] of each marker in the board frame."""
    w, h = board_size_m
    a, s = MARKER_INSET_M, MARKER_SIDE_M
    return {0: np.array([a, a]), 1: np.array([w - a - s, a]),
            2: np.array([w - a - s, h - a - s]), 3: np.array([a, h - a - s])}


def marker_corners_board(board_size_m: tuple[float, float]) -> dict[int, np.ndarray]:
    """Corners (4, 2) [m] of each marker in the board frame, in OpenCV's order.

    OpenCV's ArUco detector returns the corners of an upright marker as
    top-left, top-right, bottom-right, bottom-left; with the board's y axis
    up, that is (x0, y0+s), (x0+s, y0+s), (x0+s, y0), (x0, y0).
    """
    s = MARKER_SIDE_M
    out = {}
    for mid, (x0, y0) in marker_origins_board(board_size_m).items():
        out[mid] = np.array([[x0, y0 + s], [x0 + s, y0 + s], [x0 + s, y0], [x0, y0]])
    return out
