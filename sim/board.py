"""The whiteboard's pose and size, and the check that the arm can wipe it.

Board frame (DESIGN.md): origin at a corner, x along the width, y along the
height, z the outward normal; the board's front face is z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from arm.branch import CONTROLLER_ZONES, ENOUGH_ROOM_RAD, candidate_seeds, follow, raster, room_along_rad
from arm.robot_model import IkError, RobotModel
from interfaces.errors import ConfigError
from interfaces.transforms import matrix_from_quat_wxyz, tool_rotation_on_board, transform

from .params import BoardParams

#: Shoulder (joint 2 axis) of the iiwa 14 in the world frame [m].
SHOULDER_M = np.array([0.0, 0.0, 0.36])
#: The robot must be at least this far in front of the board plane [m].
MIN_SHOULDER_CLEARANCE_M = 0.1
#: Seed posture for inverse kinematics (elbow up, wrist bent).
SEED_Q_RAD = np.array([0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0])
#: A candidate start's way over the board is checked for the camera's markers at every this-many-th configuration
#: (:func:`arm.branch.follow` steps 1 cm; every 5th: 5 cm apart).
VIEW_EVERY = 5
#: Candidate starts keeping room within this of the most are as good along the way; the one that starts farthest
#: from its limits is taken [rad].
SAME_ROOM_RAD = 0.01

_PRESETS: dict[str, dict[str, Any]] = {
    # vertical board 0.68 m in front of the robot, x_board = -y_world, y_board = +z_world, z_board = -x_world
    "wall": dict(size_m=(0.8, 0.6), origin_m=(0.68, 0.4, 0.25),
                 R=np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])),
    # horizontal board 0.15 m above the base, x_board = -y_world, y_board = +x_world, z_board = +z_world
    "table": dict(size_m=(0.7, 0.5), origin_m=(0.30, 0.35, 0.15),
                  R=np.column_stack([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])),
}


@dataclass(frozen=True)
class Board:
    """A board: ``T_board_to_world`` (4, 4), ``size_m`` (2,) width and height, ``thickness_m``."""

    T_board_to_world: np.ndarray
    size_m: np.ndarray
    thickness_m: float

    @property
    def R(self) -> np.ndarray:
        return self.T_board_to_world[:3, :3]

    @property
    def origin_m(self) -> np.ndarray:
        return self.T_board_to_world[:3, 3]

    @property
    def normal_world(self) -> np.ndarray:
        """(3,) outward unit normal."""
        return self.R[:, 2]

    @property
    def centre_world_m(self) -> np.ndarray:
        return self.world_from_board(self.size_m / 2.0)

    def world_from_board(self, xy: np.ndarray) -> np.ndarray:
        """World points (..., 3) of board-plane points ``xy`` (..., 2) [m]."""
        xy = np.asarray(xy, float)
        return self.origin_m + xy[..., :1] * self.R[:, 0] + xy[..., 1:2] * self.R[:, 1]

    def board_from_world(self, p: np.ndarray) -> np.ndarray:
        """Board-frame coordinates (..., 3) of world points ``p`` (..., 3)."""
        return (np.asarray(p, float) - self.origin_m) @ self.R

    def tool_rotation(self) -> np.ndarray:
        """(3, 3) tool orientation facing the board: tool z into the board, pad's long side along board x."""
        return tool_rotation_on_board(self.R)


def board_from_params(params: BoardParams) -> Board:
    """The board of a preset or a custom pose (no reachability check; see :func:`check_board`)."""
    if params.preset == "custom":
        R = matrix_from_quat_wxyz(np.array(params.quat_wxyz))
        origin, size = np.array(params.origin_m), np.array(params.size_m)
    else:
        preset = _PRESETS[params.preset]
        R, origin = preset["R"], np.array(preset["origin_m"])
        size = np.array(params.size_m if params.size_m is not None else preset["size_m"])
    return Board(transform(R, origin), size, params.thickness_m)


def wipe_region(board: Board, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` (2,) board-frame corners of the area where stains may lie."""
    lo, hi = np.full(2, margin_m), board.size_m - margin_m
    if np.any(hi <= lo):
        raise ConfigError(f"board {board.size_m.tolist()} m leaves no room for stains with a margin of {margin_m} m")
    return lo, hi


def check_board(board: Board, margin_m: float, model: RobotModel | None = None) -> None:
    """Raise :class:`ConfigError` if the arm cannot wipe the board.

    The robot's shoulder must be at least 0.1 m in front of the board, and
    the pad must reach the centre and the four corners of the stain region
    flat on the board within the joint limits.
    """
    clearance = float((SHOULDER_M - board.origin_m) @ board.normal_world)
    if clearance < MIN_SHOULDER_CLEARANCE_M:
        raise ConfigError(
            f"impossible board pose: the robot's shoulder is {clearance:.2f} m in front of the board "
            f"(needs >= {MIN_SHOULDER_CLEARANCE_M} m; is the board behind the robot or facing away?)")
    model = model or RobotModel()
    lo, hi = wipe_region(board, margin_m)
    R = board.tool_rotation()
    for name, xy in (("centre", (lo + hi) / 2), ("corner lo-lo", lo), ("corner hi-lo", (hi[0], lo[1])),
                     ("corner hi-hi", hi), ("corner lo-hi", (lo[0], hi[1]))):
        p = board.world_from_board(np.array(xy))
        try:
            model.solve_ik(p, R, SEED_Q_RAD, tol_m=1e-3)
        except IkError as exc:
            raise ConfigError(f"impossible board pose: the eraser cannot reach the stain region's {name} "
                              f"at {np.round(p, 3).tolist()} m ({exc})") from None


def start_configuration(board: Board, standoff_m: float, model: RobotModel | None = None,
                        margin_m: float | None = None, camera_m: np.ndarray | None = None) -> np.ndarray:
    """(7,) joint positions with the pad facing the board centre ``standoff_m`` off its surface.

    With ``margin_m`` [m] (the stain region's margin, :func:`wipe_region`) the configuration is also chosen for
    the whole board: the one from :data:`SEED_Q_RAD` is kept if the arm, carried from it over the stain region as
    the controller's posture carries it, keeps :data:`arm.branch.ENOUGH_ROOM_RAD` to every position limit
    (:func:`start_room_rad`); otherwise the one of :func:`arm.branch.candidate_seeds` that keeps the
    most (on random board 603 the first took A1 onto its limit over the board's near edge), and of those within
    :data:`SAME_ROOM_RAD` of the most, the one that starts farthest from its limits and from A2 = 0 and A6 = 0
    (the candidates of one branch follow into the same posture and keep the same room along the way, wherever on
    the elbow's swing they start). With ``camera_m`` (3,) [m, world] too, a candidate is taken only if the arm
    leaves that camera the markers perception needs to keep a board (:data:`sim.start_view.MARKERS_HELD`) at every
    :data:`VIEW_EVERY`-th point of the way (:func:`sim.start_view.markers_hidden_at_start`; on random board 53 a
    start with room hid three of the four mid-job, perception lost the board and found it again with no stains)."""
    model = model or RobotModel()
    p = board.centre_world_m + standoff_m * board.normal_world
    R = board.tool_rotation()
    try:
        q = model.solve_ik(p, R, SEED_Q_RAD)
    except IkError as exc:
        raise ConfigError(f"impossible board pose: no start pose facing the board centre ({exc})") from None
    if margin_m is None:
        return q
    lo, hi = wipe_region(board, margin_m)
    points = [board.world_from_board(xy) for xy in raster(lo, hi)]
    room = start_room_rad(model, q, points, R)
    if room >= ENOUGH_ROOM_RAD:
        return q
    tried = [(room, _start_room(model, q, q[None]), q)]
    for seed in candidate_seeds(float(np.arctan2(p[1], p[0])), SEED_Q_RAD):
        try:
            q = model.solve_ik(p, R, seed)
        except IkError:
            continue
        way = follow(model, q, points, R, CONTROLLER_ZONES)
        if camera_m is None or _keeps_the_markers_in_view(board, model, way, camera_m):
            tried.append((_start_room(model, q, way), _start_room(model, q, q[None]), q))
    most = max(r for r, _, _ in tried)
    return max((t for t in tried if t[0] >= most - SAME_ROOM_RAD), key=lambda t: t[1])[2]


def _keeps_the_markers_in_view(board: Board, model: RobotModel, way: np.ndarray, camera_m: np.ndarray) -> bool:
    """Whether the arm at every :data:`VIEW_EVERY`-th configuration of ``way`` (k, 7) [rad] leaves the camera at
    ``camera_m`` (3,) [m, world] the markers perception keeps a found board on."""
    from .start_view import MARKERS_HELD, markers_hidden_at_start

    most = 4 - MARKERS_HELD
    return all(len(markers_hidden_at_start(board, qi, camera_m, model)) <= most for qi in way[::VIEW_EVERY])


def _start_room(model: RobotModel, q: np.ndarray, way: np.ndarray) -> float:
    return min(room_along_rad(model, np.vstack([q, way])), abs(float(q[1])), abs(float(q[5])))


def start_room_rad(model: RobotModel, q: np.ndarray, points_m: list[np.ndarray], R: np.ndarray) -> float:
    """How good a start ``q`` (7,) [rad] is for the pad (orientation ``R``) to go over ``points_m`` (each (3,) [m,
    world]): the least room to a position limit at the start and along the way (:func:`arm.branch.room_along_rad`),
    or the start's own distance of A2 or A6 from zero if less (an arm that starts stretched at the shoulder or the
    wrist leaves it on whichever side its first motion takes). The start counts itself: on random board 304 the
    candidate kept for the way's room started A6 0.058 rad from its limit, inside the controller's 0.12 rad
    margin, whose repulsion took A6 to 0.85 of its speed limit in 34 ms and the robot side braked."""
    return _start_room(model, q, follow(model, q, points_m, R, CONTROLLER_ZONES))
