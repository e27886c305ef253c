"""What the skill executor reads and writes: the board, its stains, the measured pad, the setpoint.

Positions are in the *board frame*: in-plane ``xy`` [m] from the board's
corner along its axes, height ``h`` [m] along the outward normal above the
board surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from arm.reach import ArmReach
from interfaces.transforms import tool_rotation_on_board

#: The elbow's least distance [rad] from its limit at a look point (the controller's joint-limit repulsion acts
#: within 0.12 rad; the flight there and the pose error need room beyond it; the wall board has 0.24 at its edge).
LOOK_ELBOW_ROOM_RAD = 0.2
#: Turns [rad] off the line towards the robot base tried for a look point when that line is out of reach.
LOOK_TURNS_RAD = tuple(np.radians([30.0, -30.0, 60.0, -60.0, 90.0, -90.0]))


@dataclass(frozen=True)
class BoardPose:
    """The board: ``R`` (3, 3) its axes in the world, ``origin_m`` (3,) its corner, ``size_m`` (2,)."""

    R: np.ndarray
    origin_m: np.ndarray
    size_m: np.ndarray

    @classmethod
    def from_transform(cls, T: np.ndarray, size_m) -> BoardPose:
        T = np.asarray(T, float)
        return cls(T[:3, :3].copy(), T[:3, 3].copy(), np.asarray(size_m, float).reshape(2))

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


def look_point(board: BoardPose, centres_m: list[np.ndarray], sizes_m: list[float], clearance_m: float,
               arm: ArmReach | None = None, height_m: float = 0.0, attempt: int = 0) -> np.ndarray:
    """(2,) board point [m] from which the arm leaves ``centres_m`` (stains (2,), sizes [m]) in the camera's view.

    The arm runs from the pad back towards the robot base, so the pad goes
    ``clearance_m`` beyond the stains' extent in the direction of the base
    (its projection on the board plane; the world origin), clipped into the
    board. With the base right behind the stains: along board -x.

    With ``arm``: only where the pad, ``height_m`` above the board and flat
    on it, leaves the elbow :data:`LOOK_ELBOW_ROOM_RAD` from its limit (on a
    board near the base its near edge is out of reach). If the point towards
    the base is not, the same distance turned off that line
    (:data:`LOOK_TURNS_RAD`, up to beside the stains) where it is still clear
    of them; else as far towards the base as the arm reaches (the survey of a
    whole board: no point is clear of it).

    ``attempt`` k > 0 (the stains are still waiting for kappa after k looks: the arm hid them from there
    too, e.g. a stain at a table's near edge that the links hang over from one side): the next of the points
    that qualify (towards the base, then turned), in turn, so each look sees them from elsewhere.
    """
    c = np.mean(np.asarray(centres_m, float), axis=0)
    reach = max(float(np.linalg.norm(np.asarray(x) - c)) + 0.5 * s for x, s in zip(centres_m, sizes_m))
    d = board.to_board(np.zeros(3))[:2] - c
    n = float(np.linalg.norm(d))
    d = d / n if n > 1e-6 else np.array([-1.0, 0.0])

    def at(t: float) -> np.ndarray:
        return np.clip(c + d * t, 0.0, board.size_m)

    far = reach + clearance_m
    if arm is None:
        return at(far)
    R_pad = tool_rotation_on_board(board.R)

    def roomy(xy: np.ndarray) -> bool:
        return arm.elbow_room_rad(board.to_world(np.array([*xy, height_m])), R_pad) >= LOOK_ELBOW_ROOM_RAD

    if attempt <= 0 and roomy(at(far)):
        return at(far)
    # towards the base is out of reach (a board near it), or was looked from already: turned off that line, up
    # to beside the stains (never beyond them, where the arm would reach over them), while still clear of them
    qualified = [at(far)] if roomy(at(far)) else []
    for angle in LOOK_TURNS_RAD:
        co, si = np.cos(angle), np.sin(angle)
        xy = np.clip(c + far * np.array([co * d[0] - si * d[1], si * d[0] + co * d[1]]), 0.0, board.size_m)
        if np.linalg.norm(xy - c) >= reach + 0.5 * clearance_m and roomy(xy):
            if attempt <= 0:
                return xy
            qualified.append(xy)
    if qualified:
        return qualified[attempt % len(qualified)]
    if not roomy(at(0.0)):
        return at(0.0)
    lo, hi = 0.0, far  # roomy at lo, not at hi: the elbow's room falls towards the base
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if roomy(at(mid)) else (lo, mid)
    return at(lo)
