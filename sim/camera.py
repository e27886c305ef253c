"""The fixed board camera: its pose, its pinhole model in OpenGL form, and the board's texture.

Pure numpy and OpenCV; the PyBullet call that renders lives in
:mod:`sim.renderer`. The camera frame is the optical frame (x right, y down,
z forward), like a RealSense colour stream.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from interfaces.board_markers import ARUCO_DICTIONARY, MARKER_CELLS, MARKER_SIDE_M, marker_origins_board
from interfaces.messages import CameraIntrinsics

from .board import Board
from .params import CameraParams

#: Board colour (clean) and marker ink colour, RGB.
BOARD_RGB = np.array([242, 243, 238], np.float32)
INK_RGB = np.array([28, 38, 96], np.float32)
#: Texture resolution [texels per metre].
TEXELS_PER_M = 1000.0
NEAR_M, FAR_M = 0.05, 5.0


def intrinsics_of(params: CameraParams) -> CameraIntrinsics:
    return CameraIntrinsics(params.fx, params.fy, params.cx, params.cy, params.width, params.height)


def look_at(position_m: np.ndarray, target_m: np.ndarray, up_hint: np.ndarray) -> np.ndarray:
    """(4, 4) T_camera_to_world of an optical frame at ``position_m`` looking at ``target_m``.

    Image "up" (-y) leans towards ``up_hint`` (3,).
    """
    z = np.asarray(target_m, float) - position_m
    z /= np.linalg.norm(z)
    y = -(up_hint - (up_hint @ z) * z)
    if np.linalg.norm(y) < 1e-6:
        raise ValueError("camera up hint is parallel to the viewing direction")
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = position_m
    return T


def camera_pose(params: CameraParams, board: Board) -> np.ndarray:
    """(4, 4) T_camera_to_world: configured, or automatic (board in view with the margin)."""
    up = board.R[:, 1]
    if params.position_m is not None:
        return look_at(np.array(params.position_m), np.array(params.look_at_m), up)
    half_fov_x = math.atan(params.width / 2 / params.fx)
    half_fov_y = math.atan(params.height / 2 / params.fy)
    w, h = board.size_m * (1.0 + params.margin)
    elev = math.radians(params.elevation_deg)
    distance = max(w / 2 / math.tan(half_fov_x), h / 2 / math.tan(half_fov_y)) + 0.1
    azim = math.radians(params.azimuth_deg)
    direction = (math.cos(elev) * (math.cos(azim) * board.normal_world + math.sin(azim) * board.R[:, 0])
                 + math.sin(elev) * up)
    return look_at(board.centre_world_m + distance * direction, board.centre_world_m, up)


def view_matrix(T_camera_to_world: np.ndarray) -> list[float]:
    """PyBullet view matrix (16, column-major): world -> OpenGL camera (x right, y up, z back)."""
    gl_from_optical = np.diag([1.0, -1.0, -1.0, 1.0])
    V = gl_from_optical @ np.linalg.inv(T_camera_to_world)
    return V.T.reshape(-1).tolist()


def projection_matrix(k: CameraIntrinsics, near: float = NEAR_M, far: float = FAR_M) -> list[float]:
    """PyBullet projection matrix (16, column-major) of a pinhole camera, pixel centres at integers."""
    w, h = k.width, k.height
    P = np.array([
        [2 * k.fx / w, 0.0, 1.0 - (2 * k.cx + 1.0) / w, 0.0],
        [0.0, 2 * k.fy / h, (2 * k.cy + 1.0) / h - 1.0, 0.0],
        [0.0, 0.0, -(far + near) / (far - near), -2 * far * near / (far - near)],
        [0.0, 0.0, -1.0, 0.0],
    ])
    return P.T.reshape(-1).tolist()


def project(k: CameraIntrinsics, T_camera_to_world: np.ndarray, p_world: np.ndarray) -> np.ndarray:
    """Pixel coordinates (..., 2) of world points (..., 3)."""
    T = np.linalg.inv(T_camera_to_world)
    pc = np.asarray(p_world, float) @ T[:3, :3].T + T[:3, 3]
    return np.stack([k.fx * pc[..., 0] / pc[..., 2] + k.cx, k.fy * pc[..., 1] / pc[..., 2] + k.cy], -1)


def marker_layer(board_size_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(ink, mask)`` texture-sized (H, W) uint8 images of the corner markers, row 0 at the board's top."""
    W = int(round(board_size_m[0] * TEXELS_PER_M))
    H = int(round(board_size_m[1] * TEXELS_PER_M))
    ink = np.zeros((H, W), np.uint8)
    mask = np.zeros((H, W), bool)
    side = int(round(MARKER_SIDE_M * TEXELS_PER_M))
    side -= side % MARKER_CELLS
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))
    for mid, (x0, y0) in marker_origins_board(board_size_m).items():
        img = cv2.aruco.generateImageMarker(dictionary, mid, side)
        c0 = int(round(x0 * TEXELS_PER_M))
        r0 = H - int(round(y0 * TEXELS_PER_M)) - side
        ink[r0:r0 + side, c0:c0 + side] = img < 128
        mask[r0:r0 + side, c0:c0 + side] = True
    return ink, mask


def board_texture(dirt: np.ndarray, cell_m: float, markers: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """(H, W, 3) uint8 RGB texture of the board: dirt in ink colour over white, black markers; row 0 = top."""
    ink, mask = markers
    H, W = ink.shape
    rep = max(int(round(cell_m * TEXELS_PER_M)), 1)
    d = np.repeat(np.repeat(dirt[::-1], rep, axis=0), rep, axis=1)[:H, :W]
    if d.shape != (H, W):
        d = np.pad(d, ((0, H - d.shape[0]), (0, W - d.shape[1])))
    rgb = BOARD_RGB + (INK_RGB - BOARD_RGB) * d[..., None]
    rgb[mask] = np.where(ink[mask, None], 15.0, BOARD_RGB)
    return rgb.astype(np.uint8)
