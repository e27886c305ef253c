"""What the skill executor reads and writes: the board, its stains, the measured pad, the setpoint.

Positions are in the *board frame*: in-plane ``xy`` [m] from the board's
corner along its axes, height ``h`` [m] along the outward normal above the
board surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class BoardPose:
    """The board: ``R`` (3, 3) its axes in the world, ``origin_m`` (3,) its corner, ``size_m`` (2,); ``camera_m``
    (3,) where perception's camera sees it from, in the world [m] (None: not known)."""

    R: np.ndarray
    origin_m: np.ndarray
    size_m: np.ndarray
    camera_m: np.ndarray | None = None

    @classmethod
    def from_transform(cls, T: np.ndarray, size_m, camera_m=None) -> BoardPose:
        T = np.asarray(T, float)
        camera = None if camera_m is None or len(camera_m) != 3 else np.asarray(camera_m, float).copy()
        return cls(T[:3, :3].copy(), T[:3, 3].copy(), np.asarray(size_m, float).reshape(2), camera)

    @property
    def normal(self) -> np.ndarray:
        return self.R[:, 2]

    def to_board(self, p_world: np.ndarray) -> np.ndarray:
        """(3,) board coordinates (x, y, h) of a world point."""
        return (np.asarray(p_world, float) - self.origin_m) @ self.R

    def to_world(self, xyh: np.ndarray) -> np.ndarray:
        """(3,) world point of board coordinates (x, y, h)."""
        return self.origin_m + self.R @ np.asarray(xyh, float)

    def close_to(self, other: BoardPose, tol_m: float = 0.005, tol_rad: float = 0.02) -> bool:
        moved = np.linalg.norm(self.origin_m - other.origin_m)
        turned = np.linalg.norm(self.R - other.R)  # ~ angle for small turns
        return bool(moved <= tol_m and turned <= tol_rad)


@dataclass
class ToolState:
    """The pad as measured, in the board frame: xy (2,), h [m], in-plane velocity (2,), height rate, force [N].

    R : (3, 3) pad orientation in the world; force_n : the board's push on
    the eraser along the outward normal (positive when pressing).
    """

    xy: np.ndarray
    h: float
    v_xy: np.ndarray
    v_h: float
    R: np.ndarray
    force_n: float


@dataclass
class Setpoint:
    """What the impedance and force control should do this tick (board frame, SI units).

    xy, v_xy, a_xy : in-plane reference (2,); h, v_h, a_h : reference along
    the normal (used when ``contact`` is False); R, omega, domega : pad
    orientation (3, 3) and its rates (3,), world axes; contact : regulate
    the normal force to ``force_n`` instead of tracking h.
    """

    xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    v_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    a_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    h: float = 0.0
    v_h: float = 0.0
    a_h: float = 0.0
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    domega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact: bool = False
    force_n: float = 0.0

    def xyh(self) -> np.ndarray:
        """(3,) a new array: the position (x, y, h) [m]."""
        return np.array([*self.xy, self.h])
