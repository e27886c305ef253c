"""The fixed board camera: its pose, its pinhole model in OpenGL form, the board's texture and its dirt.

Pure numpy and OpenCV; the PyBullet call that renders lives in
:mod:`sim.renderer`. The camera frame is the optical frame (x right, y down,
z forward), like a RealSense colour stream.

The board's texture (white with the corner markers) is loaded once: PyBullet's
``changeTexture`` does not reach its TinyRenderer, and reloading a texture
per frame leaks its memory. The dirt is drawn in image space instead: the
camera and the board are fixed, so every pixel's ray meets the board plane
at a fixed cell (:func:`board_cell_index`); where the rendered segmentation
says the board is visible, :func:`composite_dirt` tints the pixel with the
ink colour by that cell's dirt, keeping the rendered shading (and the
arm's shadow).
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
#: Texture resolution [texels per metre]: 2 mm texels, like the dirt grid (a 6 cm marker is 30 texels).
TEXELS_PER_M = 500.0
NEAR_M, FAR_M = 0.05, 5.0


def intrinsics_of(params: CameraParams) -> CameraIntrinsics:
    fx, fy, cx, cy = params.fx, params.fy, params.cx, params.cy
    assert fx is not None and fy is not None and cx is not None and cy is not None  # CameraParams fills them in
    return CameraIntrinsics(fx, fy, cx, cy, params.width, params.height)


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
    k = intrinsics_of(params)
    elev, azim = math.radians(params.elevation_deg), math.radians(params.azimuth_deg)
    direction = (math.cos(elev) * (math.cos(azim) * board.normal_world + math.sin(azim) * board.R[:, 0])
                 + math.sin(elev) * up)
    w, h = board.size_m
    corners = board.world_from_board(np.array([[0, 0], [w, 0], [w, h], [0, h]], float))
    centre = board.centre_world_m
    # seen at an angle, the near corners loom larger: back off until every corner is inside the margin
    distance = max(w / 2 * k.fx / k.cx, h / 2 * k.fy / k.cy)
    border = np.array([k.width, k.height]) * params.margin / 2
    for _ in range(200):
        T = look_at(centre + distance * direction, centre, up)
        px = project(k, T, corners)
        if np.all(px >= border) and np.all(px <= np.array([k.width, k.height]) - border):
            return T
        distance *= 1.03
    raise ValueError(f"no camera distance shows the whole board at elevation {params.elevation_deg} deg "
                     f"and azimuth {params.azimuth_deg} deg")


def light_towards(params: CameraParams, board: Board) -> list[float]:
    """Direction (3,) towards the light: configured, or from in front of the board and above it."""
    if params.light_direction is not None:
        return list(params.light_direction)
    d = board.normal_world + 0.5 * board.R[:, 1] + np.array([0.0, 0.0, 0.5])
    return (d / np.linalg.norm(d)).tolist()


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


def marker_layer(board_size_m: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    """The corner markers as texture patches ``(row, col, rgb (side, side, 3) uint8)``, row 0 at the board's top."""
    H = int(round(board_size_m[1] * TEXELS_PER_M))
    side = int(round(MARKER_SIDE_M * TEXELS_PER_M))
    side -= side % MARKER_CELLS
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))
    patches = []
    for mid, (x0, y0) in marker_origins_board((float(board_size_m[0]), float(board_size_m[1]))).items():
        ink = cv2.aruco.generateImageMarker(dictionary, mid, side) < 128
        rgb = np.where(ink[..., None], np.uint8(15), BOARD_RGB.astype(np.uint8)).astype(np.uint8)
        patches.append((H - int(round(y0 * TEXELS_PER_M)) - side, int(round(x0 * TEXELS_PER_M)), rgb))
    return patches


#: Colour of each quantized dirt level (256, 3) uint8.
_DIRT_LUT = (BOARD_RGB + (INK_RGB - BOARD_RGB) * np.linspace(0.0, 1.0, 256)[:, None]).round().astype(np.uint8)


def board_texture(dirt: np.ndarray, cell_m: float, markers: list[tuple[int, int, np.ndarray]],
                  board_size_m: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB texture of the board: dirt in ink colour over white, markers on top; row 0 = top.

    Dirt cells map to texels by nearest neighbour (cell and texel sizes need not match).
    """
    W = int(round(board_size_m[0] * TEXELS_PER_M))
    H = int(round(board_size_m[1] * TEXELS_PER_M))
    levels = (np.clip(dirt[::-1], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    rows = np.minimum((np.arange(H) + 0.5) / TEXELS_PER_M / cell_m, dirt.shape[0] - 1).astype(int)
    cols = np.minimum((np.arange(W) + 0.5) / TEXELS_PER_M / cell_m, dirt.shape[1] - 1).astype(int)
    rgb = _DIRT_LUT[levels[rows[:, None], cols[None, :]]]
    for r0, c0, patch in markers:
        rgb[r0:r0 + patch.shape[0], c0:c0 + patch.shape[1]] = patch
    return rgb


def board_cell_index(k: CameraIntrinsics, T_camera_to_world: np.ndarray, board: Board, cell_m: float,
                     grid_shape: tuple[int, int]) -> np.ndarray:
    """(H * W,) flat index into the dirt grid of the board cell each pixel's ray meets, or -1 off the board."""
    u, v = np.meshgrid(np.arange(k.width, dtype=float), np.arange(k.height, dtype=float))
    rays_cam = np.stack([(u - k.cx) / k.fx, (v - k.cy) / k.fy, np.ones_like(u)], -1).reshape(-1, 3)
    rays = rays_cam @ T_camera_to_world[:3, :3].T
    origin = T_camera_to_world[:3, 3]
    n = board.normal_world
    denom = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((board.origin_m - origin) @ n) / denom
    hit = origin + t[:, None] * rays
    xy = (hit - board.origin_m) @ board.R[:, :2]
    ny, nx = grid_shape
    ix = np.floor(xy[:, 0] / cell_m)
    iy = np.floor(xy[:, 1] / cell_m)
    ok = (t > 0) & np.isfinite(t) & (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    index = np.full(u.size, -1, np.int64)
    index[ok] = (iy[ok] * nx + ix[ok]).astype(np.int64)
    return index


def composite_dirt(rgb: np.ndarray, visible: np.ndarray, cell_index: np.ndarray, dirt: np.ndarray) -> None:
    """Tint, in place, the pixels of ``rgb`` (H, W, 3) uint8 where ``visible`` (H * W,) bool shows the board.

    A pixel's colour becomes ``(1 - d) c + d ink s`` with d its cell's dirt and
    s the rendered brightness relative to the clean board (light and shadow).
    """
    flat = rgb.reshape(-1, 3)
    sel = np.flatnonzero(visible & (cell_index >= 0))
    d = dirt.reshape(-1)[cell_index[sel]]
    keep = d > 1e-3
    sel, d = sel[keep], d[keep, None]
    if sel.size == 0:
        return
    c = flat[sel].astype(np.float32)
    shade = c.mean(axis=1, keepdims=True) / float(BOARD_RGB.mean())
    flat[sel] = np.clip((1.0 - d) * c + d * INK_RGB * shade, 0, 255).astype(np.uint8)


class DirtCompositor:
    """:func:`composite_dirt` for one fixed camera and board, the same pixels, at a cost that follows the dirt.

    ``cell_index`` (H * W,) is :func:`board_cell_index`'s map; the board pixels are sorted by their cell once, so
    a frame reads the dirt grid's cells, finds the few that carry ink and tints only their pixels, instead of
    gathering the dirt of every board pixel.
    """

    def __init__(self, cell_index: np.ndarray) -> None:
        cell_index = np.asarray(cell_index, np.int64).reshape(-1)
        board = np.flatnonzero(cell_index >= 0)
        order = np.argsort(cell_index[board], kind="stable")
        self._pixels = board[order]  # (n,) board pixels sorted by cell
        self._cells = cell_index[self._pixels]
        self._n_cells = int(self._cells.max()) + 1 if self._cells.size else 0
        bounds = np.searchsorted(self._cells, np.arange(self._n_cells + 1))
        self._start, self._count = bounds[:-1], np.diff(bounds)  # (n_cells,) each cell's run in _pixels

    def __call__(self, rgb: np.ndarray, visible: np.ndarray, dirt: np.ndarray) -> None:
        """Tint ``rgb`` (H, W, 3) uint8 in place where ``visible`` (H * W,) bool shows the board, by ``dirt``."""
        d_cells = dirt.reshape(-1)[:self._n_cells]
        dirty = np.flatnonzero((d_cells > 1e-3) & (self._count[:d_cells.size] > 0))
        if dirty.size == 0:
            return
        counts = self._count[dirty]
        # the pixel runs of the dirty cells, concatenated: each run's start, then +1 along it
        offsets = np.repeat(self._start[dirty] - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
        sel = self._pixels[offsets]
        shown = visible[sel]
        sel, d = sel[shown], np.repeat(d_cells[dirty], counts)[shown, None]
        if sel.size == 0:
            return
        flat = rgb.reshape(-1, 3)
        c = flat[sel].astype(np.float32)
        shade = c.mean(axis=1, keepdims=True) / float(BOARD_RGB.mean())
        flat[sel] = np.clip((1.0 - d) * c + d * INK_RGB * shade, 0, 255).astype(np.uint8)
