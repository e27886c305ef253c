"""Where the pad waits so the camera sees the stains: the executor's survey and look points (pure maths).

The arm reaches from the pad back to its base, so a pad beyond the stains
on the base's side leaves them in view of a camera in front of the board
(:func:`base_side_point`). Where the camera is known (perception reports
its position with the stains), the arm's silhouette is checked
(:mod:`arm.silhouette`): from a camera above and beside the board, the
wrist of an arm reaching over a board near its base hid a quarter of the
board at the point beyond the stains (a random campaign board, seed 248),
and a stain stayed unseen to the end. :func:`seen_look_point` then takes
the reachable point that hides the fewest of the board points to see.
"""

from __future__ import annotations

import math

import numpy as np

from arm.reach import ArmReach, pad_reach_problem
from arm.silhouette import arm_centre_lines, hidden
from interfaces.transforms import tool_rotation_on_board

from .executor_types import BoardPose

#: The elbow's least distance [rad] from its limit at a look point (the controller's joint-limit repulsion acts
#: within 0.12 rad; the flight there and the pose error need room beyond it; the wall board has 0.24 at its edge).
LOOK_ELBOW_ROOM_RAD = 0.2
#: Turns [rad] off the line towards the robot base tried for a look point when that line is out of reach.
LOOK_TURNS_RAD = tuple(np.radians([30.0, -30.0, 60.0, -60.0, 90.0, -90.0]))
#: The pad positions a camera-aware look point is chosen from: a grid of this many points along the board's width
#: and height, corners included (with the base-side point).
LOOK_GRID = (8, 6)
#: Board points the survey may leave hidden beyond the fewest any reachable point leaves, as a share of the board:
#: a point nearer the base-side one is taken if it hides at most this many more (the pad hides its own footprint
#: wherever it waits over the board; the stains it hides are seen during the job, when the arm has moved on).
SURVEY_HIDDEN_SLACK = 0.1
#: The spacing of :func:`board_targets` [m] and its inset from the board's edges [m].
BOARD_TARGET_SPACING_M, BOARD_TARGET_INSET_M = 0.05, 0.01
#: Points on each stain's rim in :func:`stain_targets` (with its centre).
STAIN_RIM_POINTS = 8



def look_point(board: BoardPose, centres_m: list[np.ndarray], sizes_m: list[float], clearance_m: float,
               arm: ArmReach | None = None, height_m: float = 0.0, attempt: int = 0,
               targets_m: np.ndarray | None = None, slack: float = 0.0) -> np.ndarray:
    """(2,) board point [m] from which the arm leaves ``centres_m`` (stains (2,), sizes [m]) in the camera's view.

    With ``arm``, the camera's position (``board.camera_m``) and ``targets_m`` (n, 2), the board points to see
    (:func:`board_targets`, :func:`stain_targets`): the point below, unless the arm hides more of them from there
    than from elsewhere, by more than the share ``slack`` of them (:func:`seen_look_point`). Without them:

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
    plain = base_side_point(board, centres_m, sizes_m, clearance_m, arm, height_m, attempt)
    if arm is None or board.camera_m is None or targets_m is None or len(targets_m) == 0:
        return plain
    return seen_look_point(board, np.asarray(targets_m, float), arm, height_m, plain, attempt, slack)


def survey_point(board: BoardPose, clearance_m: float, arm: ArmReach | None, height_m: float) -> np.ndarray:
    """(2,) board point [m] the survey waits over, ``height_m`` above the board: :func:`look_point` of the board's
    corners, keeping its :func:`board_targets` in view where the camera's position is known."""
    w, h = (float(x) for x in board.size_m)
    corners = [np.array(c) for c in ((0.0, 0.0), (w, 0.0), (0.0, h), (w, h))]
    return look_point(board, corners, [0.0] * 4, clearance_m, arm, height_m, targets_m=board_targets(board),
                      slack=SURVEY_HIDDEN_SLACK)


def hidden_at(board: BoardPose, targets_m: np.ndarray, arm: ArmReach, xy_m: np.ndarray, height_m: float) -> np.ndarray:
    """(n,) bool: which of the board points ``targets_m`` (n, 2) [m] the arm hides from the camera at
    ``board.camera_m`` with the pad ``height_m`` above ``xy_m`` (2,) [m], flat on the board (:mod:`arm.silhouette`;
    the wrist and tool capsule covers the pad's footprint); all of them when the pad is beyond the arm there."""
    assert board.camera_m is not None, "hidden_at needs the camera's position"
    pad = board.to_world(np.array([xy_m[0], xy_m[1], height_m]))
    lines, _ = arm_centre_lines(arm, pad[None], tool_rotation_on_board(board.R))
    if not np.all(np.isfinite(lines)):
        return np.ones(len(targets_m), bool)
    world = board.origin_m + np.column_stack([targets_m, np.zeros(len(targets_m))]) @ board.R.T
    return hidden(world, board.camera_m, lines)[0]


def survey_hidden(board: BoardPose, xy_m: np.ndarray, arm: ArmReach, height_m: float) -> np.ndarray:
    """(n, 2) the :func:`board_targets` [m] the arm hides, pad ``height_m`` above ``xy_m`` (:func:`hidden_at`)."""
    targets = board_targets(board)
    return targets[hidden_at(board, targets, arm, xy_m, height_m)]


def resurvey_point(board: BoardPose, first_xy_m: np.ndarray, arm: ArmReach | None,
                   height_m: float) -> np.ndarray | None:
    """(2,) board point [m] for a second survey look, ``height_m`` above the board: where the arm hides the fewest
    of the board points it hid at the first survey point ``first_xy_m`` (2,) [m] (:func:`survey_hidden`,
    :func:`seen_look_point` without slack). None when the first hid none, no reachable point hides fewer of them,
    or the camera's position or the arm is not known.

    The survey's point may hide a share of the board (:data:`SURVEY_HIDDEN_SLACK`, the pad's own footprint at
    the least) on the premise that a stain there is seen once the arm moves on to another; a stain hidden there
    on a board with no other is never seen (a random campaign board, seed 456: the pad waited 40 mm above its
    only stain and the cell went DONE at 0 %)."""
    if arm is None or board.camera_m is None:
        return None
    first = np.asarray(first_xy_m, float)
    hid = survey_hidden(board, first, arm, height_m)
    if len(hid) == 0:
        return None
    xy = seen_look_point(board, hid, arm, height_m, first)
    if np.linalg.norm(xy - first) < 0.005 or hidden_at(board, hid, arm, xy, height_m).all():
        return None
    return xy


def base_side_point(board: BoardPose, centres_m: list[np.ndarray], sizes_m: list[float], clearance_m: float,
                    arm: ArmReach | None = None, height_m: float = 0.0, attempt: int = 0) -> np.ndarray:
    """(2,) :func:`look_point` without the camera's position: beyond the stains on the robot base's side."""
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


def board_targets(board: BoardPose) -> np.ndarray:
    """(n, 2) board points [m] a survey must see: a grid over the whole board (:data:`BOARD_TARGET_SPACING_M`)."""
    w, h = (float(v) for v in board.size_m)
    cols = max(2, int(round((w - 2 * BOARD_TARGET_INSET_M) / BOARD_TARGET_SPACING_M)) + 1)
    rows = max(2, int(round((h - 2 * BOARD_TARGET_INSET_M) / BOARD_TARGET_SPACING_M)) + 1)
    gx, gy = np.meshgrid(np.linspace(BOARD_TARGET_INSET_M, w - BOARD_TARGET_INSET_M, cols),
                         np.linspace(BOARD_TARGET_INSET_M, h - BOARD_TARGET_INSET_M, rows))
    return np.column_stack([gx.ravel(), gy.ravel()])


def stain_targets(centres_m: list[np.ndarray], sizes_m: list[float]) -> np.ndarray:
    """(n, 2) board points [m] a look at the stains must see: each centre (2,) and :data:`STAIN_RIM_POINTS` on a
    circle of its size [m] across."""
    a = np.linspace(0.0, 2.0 * math.pi, STAIN_RIM_POINTS, endpoint=False)
    rim = np.column_stack([np.cos(a), np.sin(a)])
    return np.vstack([np.vstack([np.asarray(c, float), np.asarray(c, float) + 0.5 * s * rim])
                      for c, s in zip(centres_m, sizes_m)])


def seen_look_point(board: BoardPose, targets_m: np.ndarray, arm: ArmReach, height_m: float,
                    preferred: np.ndarray, attempt: int = 0, slack: float = 0.0) -> np.ndarray:
    """(2,) board point [m] for the pad, ``height_m`` above the board and flat on it, from which the arm hides the
    fewest of ``targets_m`` (n, 2) [m] from the camera at ``board.camera_m``.

    The candidates are ``preferred`` (2,) and a :data:`LOOK_GRID` over the board, each where the elbow has
    :data:`LOOK_ELBOW_ROOM_RAD` and the pad is within reach (:func:`~arm.reach.pad_reach_problem`; checked
    for the few near the best only). Of those
    hiding at most the share ``slack`` of the targets more than the best, the nearest to ``preferred``
    (itself if it is one); ``attempt`` k > 0: the k-th nearest, so each look sees from elsewhere.
    """
    assert board.camera_m is not None, "seen_look_point needs the camera's position"
    R_pad = tool_rotation_on_board(board.R)
    w, h = (float(v) for v in board.size_m)
    gx, gy = np.meshgrid(np.linspace(0.0, w, LOOK_GRID[0]), np.linspace(0.0, h, LOOK_GRID[1]))
    xy = np.vstack([np.asarray(preferred, float)[None], np.column_stack([gx.ravel(), gy.ravel()])])
    pads = board.origin_m + np.column_stack([xy, np.full(len(xy), height_m)]) @ board.R.T
    lines, elbow = arm_centre_lines(arm, pads, R_pad)
    roomy = arm.q4_max_rad - elbow >= LOOK_ELBOW_ROOM_RAD
    roomy[0] = np.isfinite(elbow[0])  # the base-side point: chosen for its room already, or the best there is
    if not roomy.any():
        return np.asarray(preferred, float)
    xy, pads, lines = xy[roomy], pads[roomy], lines[roomy]
    world = board.origin_m + np.column_stack([targets_m, np.zeros(len(targets_m))]) @ board.R.T
    count = hidden(world, board.camera_m, lines).sum(axis=1)
    allowed = math.floor(slack * len(targets_m))
    order = np.argsort(np.linalg.norm(xy - preferred, axis=1), kind="stable")
    best = [int(i) for i in order if count[i] <= count.min() + allowed
            and (i == 0 and roomy[0] or pad_reach_problem(arm, pads[i], R_pad) is None)]
    return xy[best[attempt % len(best)] if best else 0].copy()
