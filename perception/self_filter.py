"""The robot's own tool, masked out of the board image (a self-filter): the eraser is not ink.

The camera sees the eraser whenever the arm is over the board, and its
holder can have any colour, the ink's included (the sim's is blue like
the marker): classified by colour alone, the eraser hovering at a look point
or pressing at the board's near edge read as ink that no wiping removes, and
the controller re-passed a clean stain until it gave it up. The robot's
joint states say where the tool is: its box (the pad ``PAD_SIZE_M`` by
``ERASER_DEPTH_M`` behind the pad face, the TCP frame's z out of the pad)
is projected from the camera's centre onto the board plane and the pixels
it covers there are occluded, not judged. The rest of the arm is left to
the colour model (grey and orange links are far from it).

Pure maths here (:func:`tool_corners`, :func:`board_shadow`,
:func:`shadow_mask`); :class:`ToolTrack` keeps the robot's recent joint
states and gives the tool at a frame's time, with a forward kinematics of
the shared description.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from arm.description import ERASER_DEPTH_M, PAD_SIZE_M

from .rectify import BoardGrid

#: The tool box's corners in the TCP frame (8, 3) [m]: the pad face at z = 0, the holder behind it (z < 0).
TOOL_CORNERS_TCP = np.array([[sx * PAD_SIZE_M[0] / 2, sy * PAD_SIZE_M[1] / 2, z]
                             for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, -ERASER_DEPTH_M)])
#: Points closer than this to the camera's plane parallel to the board (or beyond it) are not projected [m].
MIN_DEPTH_M = 1e-3


def tool_corners(p_world_m: np.ndarray, R_world: np.ndarray) -> np.ndarray:
    """World points (8, 3) [m] of the tool box for a TCP at ``p_world_m`` (3,) with orientation ``R_world`` (3, 3)."""
    return TOOL_CORNERS_TCP @ np.asarray(R_world, float).T + np.asarray(p_world_m, float)


def board_shadow(points_world_m: np.ndarray, T_board_to_world: np.ndarray, camera_world_m: np.ndarray
                 ) -> np.ndarray:
    """Board-plane points (k, 2) [m] where the camera's rays through ``points_world_m`` (n, 3) meet the board.

    The camera centre ``camera_world_m`` (3,) must be in front of the board (board z > 0); points on or
    behind the camera's side of it (z >= the camera's) have no such ray and are left out (k <= n).
    """
    R, o = T_board_to_world[:3, :3], T_board_to_world[:3, 3]
    c = (np.asarray(camera_world_m, float) - o) @ R
    if c[2] <= MIN_DEPTH_M:
        return np.zeros((0, 2))
    p = (np.asarray(points_world_m, float).reshape(-1, 3) - o) @ R
    p = p[p[:, 2] < c[2] - MIN_DEPTH_M]
    t = c[2] / (c[2] - p[:, 2])  # c + t (p - c) has z = 0
    return c[:2] + t[:, None] * (p[:, :2] - c[:2])


#: The pad wipes where its face is within this of perception's board plane [m]: its contact, with the error of the
#: board's pose along its normal (the controller's touches find the surface up to 27 mm from it, 8.6 mm at the
#: median, docs/campaigns.md); a hover over a stain (40 mm) is not.
PAD_ON_BOARD_M = 0.03


def pad_footprint(tool_world_m: np.ndarray, T_board_to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The pad face's box on the board (low (2,), high (2,)) [m, board frame] when the face (the corners of
    ``tool_world_m`` (8, 3) [m] at the TCP's z = 0, :data:`TOOL_CORNERS_TCP`) is within :data:`PAD_ON_BOARD_M`
    of the board plane; None while the pad is off the board (over it in the air, or away)."""
    R, o = T_board_to_world[:3, :3], T_board_to_world[:3, 3]
    face = (np.asarray(tool_world_m, float).reshape(-1, 3)[TOOL_CORNERS_TCP[:, 2] == 0.0] - o) @ R
    if np.abs(face[:, 2]).max() > PAD_ON_BOARD_M:
        return None
    return face[:, :2].min(axis=0), face[:, :2].max(axis=0)


def shadow_mask(grid: BoardGrid, shadow_xy_m: np.ndarray, margin_m: float) -> np.ndarray:
    """(rows, cols) bool of the rectified board: the convex hull of ``shadow_xy_m`` (k, 2) [m] grown by
    ``margin_m`` [m]; all False for fewer than three points."""
    rows, cols = grid.shape
    mask: np.ndarray = np.zeros((rows, cols), np.uint8)
    if len(shadow_xy_m) < 3:
        return mask.view(bool)
    r = grid.resolution_m
    px = np.column_stack([shadow_xy_m[:, 0] / r - 0.5, rows - shadow_xy_m[:, 1] / r - 0.5])
    # far outside the grid (a grazing ray): clip so the polygon stays drawable; the board part is unchanged
    px = np.clip(px, -4.0 * max(rows, cols), 5.0 * max(rows, cols))
    hull = cv2.convexHull(np.round(px * 16).astype(np.int32))  # 4 fractional bits
    cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=4)
    k = int(np.ceil(margin_m / r))
    if k > 0:
        mask = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1)))
    return mask.view(bool)


@dataclass(frozen=True)
class ArmState:
    """The arm as the joint state nearest a frame says: ``q_rad`` (7,), ``dq_rad_s`` (7,), and ``age_s``, how
    far that state's time is from the frame's [s] (either way); masked by :mod:`perception.arm_mask`."""

    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    age_s: float


class ToolTrack:
    """The robot's recent joint states and the tool's pose at a frame's time.

    The perception loop, at each frame, :meth:`add` s the states received
    since the last one (robot clock [ns], joint positions (7,) [rad], the
    monotonic time [s] they were taken) and asks :meth:`corners_at`. A frame
    stamped with the robot's clock gets the state nearest that time; a frame
    without it (a real camera: 0) the newest state. Either is used only if it
    is within ``max_age_s`` of the frame (robot clock) or of now (taken): a
    robot side that went silent leaves the frames unmasked, counted.

    Attributes
    ----------
    used, unknown : int
        Frames given a tool pose, and frames without one (no state near enough).
    """

    def __init__(self, max_age_s: float, history: int = 512) -> None:
        from arm.robot_model import RobotModel

        self.max_age_s = float(max_age_s)
        self._states: deque[tuple[int, float, np.ndarray, np.ndarray]] = deque(maxlen=history)
        self._model = RobotModel()
        self.used = 0
        self.unknown = 0

    def add(self, robot_time_ns: int, q_rad, arrived_s: float, dq_rad_s=None) -> None:
        q = np.asarray(q_rad, float)
        dq = np.zeros_like(q) if dq_rad_s is None else np.asarray(dq_rad_s, float)
        if q.shape != (self._model.nq,) or not np.isfinite(q).all() or dq.shape != q.shape \
                or not np.isfinite(dq).all():
            return  # the decoder checked the message; a wrong arm is not ours to mask
        self._states.append((int(robot_time_ns), float(arrived_s), q, dq))

    def _nearest(self, frame_robot_time_ns: int, now_s: float, count: bool = True
                 ) -> tuple[np.ndarray, np.ndarray, float] | None:
        """``(q, dq, age_s)`` of the state for the frame (the class docstring), or None; counted (``count``)."""
        states = self._states
        got = None
        if states and frame_robot_time_ns > 0:
            t, _, q_near, dq = min(states, key=lambda s: abs(s[0] - frame_robot_time_ns))
            if abs(t - frame_robot_time_ns) * 1e-9 <= self.max_age_s:
                got = q_near, dq, (frame_robot_time_ns - t) * 1e-9
        elif states and now_s - states[-1][1] <= self.max_age_s:
            got = states[-1][2], states[-1][3], now_s - states[-1][1]
        if count:
            self.used += got is not None
            self.unknown += got is None
        return got

    def corners_at(self, frame_robot_time_ns: int, now_s: float) -> np.ndarray | None:
        """World points (8, 3) [m] of the tool box at the frame's time, or None (no state near enough)."""
        got = self._nearest(frame_robot_time_ns, now_s)
        return None if got is None else tool_corners(*self._model.tcp_pose(got[0]))

    def arm_at(self, frame_robot_time_ns: int, now_s: float) -> ArmState | None:
        """The :class:`ArmState` for the frame (joint positions and speeds, and how far the state is from the
        frame's time), or None (no state near enough)."""
        got = self._nearest(frame_robot_time_ns, now_s, count=False)  # counted once, by corners_at
        return None if got is None else ArmState(got[0], got[1], float(got[2]))
