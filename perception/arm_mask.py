"""The whole arm masked out of the board image from the robot's joint states (the self-filter, every link).

A real iiwa's links are light grey (board-like: read as clean board, they
would hide a stain and let kappa come), its joints, wrist and cable dark
(read as black ink where black is in the palette). Its joint states say
where every link is: each visual shape of the shared description
(``arm/description/iiwa14_eraser.urdf``: one cylinder per link, the
eraser's boxes), as a convex solid of :data:`SIDES`-gon rings, is placed
by the forward kinematics (Pinocchio, the same file), projected from the
camera's centre onto the board plane (:func:`~perception.self_filter.board_shadow`)
and the convex hull of each solid's shadow is filled; the union is grown
by a margin. The state is seldom the frame's instant: it is ``age_s``
older (or newer), and the arm moves, so the margin is ``margin_m + |age_s|
v_max``, ``v_max`` the fastest point of the arm at that state (``dq``, by
a finite difference of the kinematics). Those pixels are occluded: never
ink, never clean (:mod:`perception.classify`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np

from arm.description import URDF_PATH, urdf_attr, urdf_child

from .rectify import BoardGrid
from .self_filter import ArmState, board_shadow

__all__ = ["ArmSilhouette", "ArmState", "link_solids", "solid_vertices"]

#: Sides of the polygon standing for a cylinder's circle (its hull then lies within 1.5 % of the circle).
SIDES = 16
#: Step of the finite difference that gives the arm's point speeds [s].
SPEED_DT_S = 0.01


def _rotation_rpy(r: float, p: float, y: float) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: ``Rz(y) Ry(p) Rx(r)``."""
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def solid_vertices(geometry: ET.Element) -> np.ndarray | None:
    """Vertices (n, 3) [m] of a URDF ``<geometry>`` (cylinder along z, box) in its own frame, or None for a
    shape without a convex polygon here (a mesh, a sphere)."""
    cyl, box = geometry.find("cylinder"), geometry.find("box")
    if cyl is not None:
        r, length = float(urdf_attr(cyl, "radius")), float(urdf_attr(cyl, "length"))
        a = 2.0 * np.pi * np.arange(SIDES) / SIDES
        ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
        return np.vstack([np.column_stack([ring, np.full(SIDES, z)]) for z in (-length / 2, length / 2)])
    if box is not None:
        sx, sy, sz = (float(v) / 2 for v in urdf_attr(box, "size").split())
        return np.array([[x, y, z] for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)])
    return None


def link_solids(urdf_path: Path = URDF_PATH) -> list[tuple[str, np.ndarray]]:
    """``(link name, vertices (n, 3) [m] in the link frame)`` of every visual shape of the description."""
    out = []
    for link in ET.parse(urdf_path).getroot().iter("link"):
        for visual in link.findall("visual"):
            v = solid_vertices(urdf_child(visual, "geometry"))
            if v is None:
                continue
            origin = visual.find("origin")
            xyz = np.array([float(x) for x in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
            rpy = [float(x) for x in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
            out.append((urdf_attr(link, "name"), v @ _rotation_rpy(*rpy).T + xyz))
    return out


class ArmSilhouette:
    """The arm's shadow from the camera on the board, from a joint state (module docstring)."""

    def __init__(self, urdf_path: Path = URDF_PATH) -> None:
        import pinocchio as pin

        self._pin = pin
        self.model = pin.buildModelFromUrdf(str(urdf_path))
        self.data = self.model.createData()
        solids = link_solids(urdf_path)
        self.frames = [self.model.getFrameId(name) for name, _ in solids]
        self.vertices = [v for _, v in solids]

    def points_world(self, q_rad: np.ndarray) -> list[np.ndarray]:
        """Per solid, its vertices (n, 3) [m] in the world (robot base) frame at joint positions ``q_rad``."""
        self._pin.framesForwardKinematics(self.model, self.data, np.asarray(q_rad, float))
        out = []
        for f, v in zip(self.frames, self.vertices):
            oMf = self.data.oMf[f]
            out.append(v @ oMf.rotation.T + oMf.translation)
        return out

    def fastest_point_m_s(self, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> float:
        """The largest speed [m/s] of any vertex of the arm at ``q_rad`` moving at ``dq_rad_s``."""
        now = np.vstack(self.points_world(q_rad))
        ahead = np.vstack(self.points_world(np.asarray(q_rad, float) + SPEED_DT_S * np.asarray(dq_rad_s, float)))
        return float(np.linalg.norm(ahead - now, axis=1).max() / SPEED_DT_S)

    def margin_m(self, arm: ArmState, margin_m: float) -> float:
        """``margin_m + |age_s| v_max`` [m] (module docstring)."""
        return margin_m + abs(arm.age_s) * self.fastest_point_m_s(arm.q_rad, arm.dq_rad_s)

    def board_mask(self, grid: BoardGrid, T_board_to_world: np.ndarray, camera_world_m: np.ndarray, arm: ArmState,
                   margin_m: float) -> np.ndarray:
        """(rows, cols) bool of the rectified board: every solid's shadow from ``camera_world_m`` (3,) [m]
        filled, grown by :meth:`margin_m`."""
        rows, cols = grid.shape
        mask: np.ndarray = np.zeros((rows, cols), np.uint8)
        r = grid.resolution_m
        lim = 4.0 * max(rows, cols)
        for pts in self.points_world(arm.q_rad):
            xy = board_shadow(pts, T_board_to_world, camera_world_m)
            if len(xy) < 3:
                continue
            px = np.clip(np.column_stack([xy[:, 0] / r - 0.5, rows - xy[:, 1] / r - 0.5]), -lim, lim + max(rows, cols))
            hull = cv2.convexHull(np.round(px * 16).astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=4)
        k = int(np.ceil(self.margin_m(arm, margin_m) / r))
        if k > 0 and mask.any():
            mask = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1)))
        return mask.view(bool)
