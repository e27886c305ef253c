"""The demonstration's own surface frame: a plane fitted to the wiping motion.

MPs are learned in this frame and executed in a target board's frame, so a
skill demonstrated on a table works on a wall board. The frame is:

- origin: centroid of the fitted (wiping) samples,
- z: the plane normal (least-variance direction), pointing to the side the
  tool approaches from (where off-plane samples lie), i.e. out of the board,
- y: "up the board": world +z projected into the plane, when the plane is
  not close to horizontal; otherwise the projection of world +y,
- x = y cross z, so (x, y, z) is right-handed, like the board frame of the design
  (x along the width, y along the height, z the outward normal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lampskit.errors import LearningError

#: |normal . world_z| above this counts as a horizontal surface (table).
HORIZONTAL_COS = 0.9


@dataclass(frozen=True)
class SurfaceFrame:
    """Pose of a surface frame in the world frame.

    Attributes
    ----------
    T_surface_to_world : array, shape (4, 4)
        Homogeneous transform mapping surface coordinates to world coordinates.
    rms_off_plane_m : float
        RMS distance of the fitted samples from the plane [m].
    """

    T_surface_to_world: np.ndarray
    rms_off_plane_m: float = 0.0

    def __post_init__(self) -> None:
        T = np.asarray(self.T_surface_to_world, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise LearningError(f"T_surface_to_world must be a finite (4, 4) matrix, got shape {T.shape}")
        R = T[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
            raise LearningError("T_surface_to_world's rotation part is not a proper rotation")
        T.setflags(write=False)
        object.__setattr__(self, "T_surface_to_world", T)

    def surface_from_world(self, points_m: np.ndarray) -> np.ndarray:
        """Points (..., 3) in the world frame -> (..., 3) in the surface frame [m]."""
        R, p = self.T_surface_to_world[:3, :3], self.T_surface_to_world[:3, 3]
        return (np.asarray(points_m) - p) @ R

    def world_from_surface(self, points_m: np.ndarray) -> np.ndarray:
        """Points (..., 3) in the surface frame -> (..., 3) in the world frame [m]."""
        R, p = self.T_surface_to_world[:3, :3], self.T_surface_to_world[:3, 3]
        return np.asarray(points_m) @ R.T + p

    def to_dict(self) -> dict:
        return {"T_surface_to_world": self.T_surface_to_world.tolist(), "rms_off_plane_m": self.rms_off_plane_m}

    @classmethod
    def from_dict(cls, d: dict) -> SurfaceFrame:
        return cls(np.asarray(d["T_surface_to_world"], dtype=float), float(d.get("rms_off_plane_m", 0.0)))


def fit_surface_frame(plane_points_m: np.ndarray, all_points_m: np.ndarray | None = None) -> SurfaceFrame:
    """Fit the surface frame (see module docstring).

    Parameters
    ----------
    plane_points_m : array, shape (K, 3)
        Samples that lie on the surface (the periodic, wiping samples) [m].
    all_points_m : array, shape (T, 3), optional
        Every sample, used only to orient the normal toward the side the
        tool comes from; default ``plane_points_m``.
    """
    pts = np.asarray(plane_points_m, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise LearningError(f"need at least 3 points of shape (K, 3) to fit a plane, got {pts.shape}")
    centroid = pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(pts - centroid, full_matrices=False)
    if sv[1] < 1e-4 * max(sv[0], 1e-12):
        raise LearningError("the wiping samples lie on a line; their surface plane is undefined")
    normal = vt[2]
    others = pts if all_points_m is None else np.asarray(all_points_m, dtype=float)
    offsets = (others - centroid) @ normal
    # the tool leaves the surface on the outward side; with no lift-off, face world +z / toward the origin
    lever = offsets[np.abs(offsets) > 3 * np.sqrt(np.mean(((pts - centroid) @ normal) ** 2)) + 1e-4]
    if lever.size:
        sign = np.sign(np.sum(lever))
    else:
        sign = np.sign(normal[2]) if abs(normal[2]) > 0.5 else np.sign(-(centroid @ normal))
    normal = normal * (sign if sign != 0 else 1.0)
    up = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < HORIZONTAL_COS else np.array([0.0, 1.0, 0.0])
    y_axis = up - (up @ normal) * normal
    y_axis /= np.linalg.norm(y_axis)
    x_axis = np.cross(y_axis, normal)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x_axis, y_axis, normal])
    T[:3, 3] = centroid
    rms = float(np.sqrt(np.mean(((pts - centroid) @ normal) ** 2)))
    return SurfaceFrame(T, rms)
