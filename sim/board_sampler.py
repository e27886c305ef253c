"""Random boards over the arm's reachable workspace: seeded, reproducible, each checked as the simulator checks any.

A board is drawn from its seed (``numpy.random.default_rng([seed, STREAM])``)::

    tilt  theta ~ U[0, 90] deg      from horizontal (0: a table facing up, 90: a wall)
    turn  psi   ~ U[-45, 45] deg    about the vertical, away from facing the robot's base axis
    roll  phi   ~ U[-45, 45] deg    about the board normal
    size  w ~ U[0.6, 0.9] m, h ~ U[0.45, 0.65] m
    centre: azimuth alpha ~ U[-45, 45] deg about the base's z axis from world x, horizontal distance
            rho ~ U[0.35, 0.85] m from the base axis, height z ~ U[0.0, 0.8] m

The normal (board z, out of the face, towards the robot) is ``n = sin(theta) (-u) + cos(theta) z_world``
with ``u = (cos(alpha + psi), sin(alpha + psi), 0)`` the horizontal direction the board looks away
along; board x runs along the width, horizontal before the roll (``(sin b, -cos b, 0)``, b = alpha +
psi: the wall preset's for alpha = psi = 0), board y = n x x. A draw is kept only if the simulator
would start on it with up to ``MAX_STAINS`` stains (:func:`board_refusal`: every corner above the
robot's mounting plane, then :func:`sim.board.check_board`, :func:`sim.board.start_configuration`,
the camera's pose with enough of the board's markers in its view past the arm at its start pose
(:func:`sim.start_view.start_view_problem`) and the stains' placement, as :class:`sim.core.SimCore` does) and
the controller would wipe a stain anywhere on its stain region (:func:`region_reach_problem`: the pad flat on
every point of a ``REACH_GRID_M`` grid over the region and ``REACH_BEYOND_M`` beyond it passes
:func:`arm.reach.pad_reach_problem`, the test the controller skips a stain by); otherwise the next draw of the
same generator is tried, up to ``MAX_TRIES``. The draws refused and why are returned, so a campaign can count them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from arm.reach import ArmReach, arm_reach, pad_reach_problem
from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from interfaces.transforms import quat_wxyz_from_matrix

from .board import Board, wipe_region

#: The generator's second seed word: the boards' stream, apart from any other use of the cell's seed.
STREAM = 48
#: Draws tried for one seed before giving up.
MAX_TRIES = 400
#: The lowest a board's corner may be above the robot's mounting plane [m].
MIN_CORNER_HEIGHT_M = 0.02
#: The most stains a random board must take (``lamps campaign --stains 1-6``).
MAX_STAINS = 6
#: The spacing of the points a board's stain region is checked at for the arm's reach [m].
REACH_GRID_M = 0.02
#: How far beyond the stain region the reach is checked [m]: perception's extent of a stain at the region's edge.
REACH_BEYOND_M = 0.01
#: The prefix of a random board's name (``random:17``: the board of seed 17).
PREFIX = "random:"


@dataclass(frozen=True)
class BoardDraw:
    """One drawn board: its ``[sim.board]`` table, the angles it was drawn with [deg] (tilt from horizontal,
    turn about the vertical, roll about the normal), and the draws refused before it, each with its reason."""

    table: dict[str, Any]
    tilt_deg: float
    turn_deg: float
    roll_deg: float
    refused: list[str] = field(default_factory=list)


def rotation_from_angles(tilt_deg: float, look_deg: float, roll_deg: float) -> np.ndarray:
    """(3, 3) board-to-world rotation (columns: board x, y, z) of a board tilted ``tilt_deg`` from horizontal,
    looking away from the robot along azimuth ``look_deg`` (alpha + psi), rolled ``roll_deg`` about its normal."""
    t, b, r = (math.radians(v) for v in (tilt_deg, look_deg, roll_deg))
    u = np.array([math.cos(b), math.sin(b), 0.0])
    n = -math.sin(t) * u + math.cos(t) * np.array([0.0, 0.0, 1.0])
    x0 = np.array([math.sin(b), -math.cos(b), 0.0])
    y0 = np.cross(n, x0)
    x = math.cos(r) * x0 + math.sin(r) * y0
    y = np.cross(n, x)
    return np.column_stack([x, y, n])


def region_reach_problem(board: Board, margin_m: float, reach: ArmReach) -> str | None:
    """Why the controller would skip a stain somewhere on ``board``'s stain region (``margin_m`` [m] in from its edges;
    None: nowhere): the first point of the ``REACH_GRID_M`` grid over the region grown by ``REACH_BEYOND_M``
    where the pad, flat on the board, is beyond the arm (:func:`arm.reach.pad_reach_problem`)."""
    lo, hi = wipe_region(board, margin_m)
    lo, hi = np.maximum(lo - REACH_BEYOND_M, 0.0), np.minimum(hi + REACH_BEYOND_M, board.size_m)
    counts = np.ceil((hi - lo) / REACH_GRID_M).astype(int) + 1
    R = board.tool_rotation()
    for x in np.linspace(lo[0], hi[0], counts[0]):
        for y in np.linspace(lo[1], hi[1], counts[1]):
            why = pad_reach_problem(reach, board.world_from_board(np.array([x, y])), R)
            if why is not None:
                return f"the stain region's point ({x:.2f}, {y:.2f}) m is {why}"
    return None


def board_refusal(table: dict[str, Any], model: RobotModel, seed: int = 0,
                  reach: ArmReach | None = None) -> str | None:
    """Why the simulator would refuse to start on the ``[sim.board]`` ``table`` with ``MAX_STAINS`` stains drawn
    from ``seed``, or the controller would skip a stain on it (:func:`region_reach_problem`, with ``reach``,
    default ``model``'s); None: neither."""
    from .board import board_from_params, check_board, start_configuration
    from .camera import camera_pose
    from .core import make_stains
    from .params import SimParams
    from .start_view import start_view_problem

    params = SimParams.from_table({"board": table, "seed": seed, "dirt": {"stains": MAX_STAINS}})
    board = board_from_params(params.board)
    w, h = board.size_m
    corners = [board.world_from_board(np.array(c)) for c in ((0, 0), (w, 0), (0, h), (w, h))]
    low = min(float(c[2]) for c in corners)
    if low < MIN_CORNER_HEIGHT_M:
        return f"a corner {low:.2f} m above the robot's mounting plane (at least {MIN_CORNER_HEIGHT_M} m)"
    try:  # the closed-form reach first: it refuses most draws the IK of check_board would, in a fraction of the time
        why = region_reach_problem(board, params.dirt.margin_m, reach or arm_reach(model))
        if why is not None:
            return why
        check_board(board, params.dirt.margin_m, model)
        camera_m = camera_pose(params.camera, board)[:3, 3] if params.camera.enabled else None
        q0 = start_configuration(board, params.start_standoff_m, model, params.dirt.margin_m, camera_m)
        if camera_m is not None:
            why = start_view_problem(board, q0, camera_m, model)
            if why is not None:
                return why
        make_stains(params, board)
    except (ConfigError, ValueError) as exc:
        return str(exc)
    return None


def sample_board(seed: int, model: RobotModel | None = None) -> BoardDraw:
    """The board of ``seed`` (module docstring). Raises :class:`ConfigError` if no draw passes in ``MAX_TRIES``."""
    if seed < 0:
        raise ConfigError(f"a random board's seed must be >= 0, got {seed}")
    model = model or RobotModel()
    reach = arm_reach(model)
    rng = np.random.default_rng([seed, STREAM])
    refused: list[str] = []
    for _ in range(MAX_TRIES):
        tilt, turn, roll = rng.uniform(0.0, 90.0), rng.uniform(-45.0, 45.0), rng.uniform(-45.0, 45.0)
        w, h = rng.uniform(0.6, 0.9), rng.uniform(0.45, 0.65)
        alpha, rho, z = math.radians(rng.uniform(-45.0, 45.0)), rng.uniform(0.35, 0.85), rng.uniform(0.0, 0.8)
        R = rotation_from_angles(tilt, math.degrees(alpha) + turn, roll)
        centre = np.array([rho * math.cos(alpha), rho * math.sin(alpha), z])
        origin = centre - R[:, 0] * w / 2 - R[:, 1] * h / 2
        table = {"preset": "custom", "origin_m": [round(float(v), 6) for v in origin],
                 "quat_wxyz": [round(float(v), 9) for v in quat_wxyz_from_matrix(R)],
                 "size_m": [round(float(w), 4), round(float(h), 4)]}
        why = board_refusal(table, model, seed, reach)
        if why is None:
            return BoardDraw(table, float(tilt), float(turn), float(roll), refused)
        refused.append(why)
    raise ConfigError(f"no reachable random board for seed {seed} in {MAX_TRIES} draws (the last refused: "
                      f"{refused[-1]})")


def random_seed_of(board: str) -> int | None:
    """The seed of a ``random:N`` board name, None for another name; :class:`ConfigError` for a bad N."""
    if not board.startswith(PREFIX):
        return None
    text = board[len(PREFIX):]
    if not text.isdigit():
        raise ConfigError(f"board {board!r}: a random board is {PREFIX}N with N a non-negative integer seed")
    return int(text)


def random_board_table(board: str) -> dict[str, Any]:
    """The ``[sim.board]`` table of the board named ``random:N``; :class:`ConfigError` for another name."""
    seed = random_seed_of(board)
    if seed is None:
        raise ConfigError(f"board {board!r} is not {PREFIX}N")
    return sample_board(seed).table
