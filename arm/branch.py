"""Which of the arm's configurations for a start pose keeps its joints off their limits over a whole board.

A pad pose has many joint configurations: the elbow's swing (the
self-motion, :mod:`arm.posture`) and, for each swing, the shoulder's and the
wrist's two branches (A2's and A6's signs: ``(q1 + pi, -q2, q3 + pi)`` is the
same arm). The controller moves the pad, never the branch: its nullspace
posture pushes A2 and A6 out of their singular zones on the side they are on
and the swing follows (:func:`arm.posture.planned_rest_posture`). So the
configuration the arm starts in decides where its joints stand over every
stain. On random board 603 the simulator's start (A1 0.54, A2 -0.31 rad)
took A1 onto its limit over the board's near edge (2.91 rad of 2.97); the
pad ran 35 mm off its reference and the passes left 2.4 % of the dirt. From
another start on the same pad pose (A1 -2.23, A2 -1.49, A6 -1.94 rad) the
cell cleaned 99.7 %, tracking 2.5 mm.

:func:`follow` moves the pad, flat, from the start pose through a list of
points as the controller's posture would carry the arm (damped least squares
on the pose, the clearance's gradient in the nullspace, small steps);
:func:`branch_room_rad` is the least room any joint but the elbow (fixed by
the pad pose alone) keeps to its position limit along the way. Pure maths on
a private Pinocchio data object.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .posture import ClearanceZones, clearance_gradient
from .robot_model import RobotModel

#: The pad's step along the way between points [m].
STEP_M = 0.01
#: Joint step bound per iteration [rad] (as :data:`arm.posture.STEP_RAD`).
STEP_RAD = 0.02
#: Iterations at each step of the pad: the posture settles a little behind it, as in the controller.
ITER_PER_STEP = 4
#: A2 and A6 stay this far on the side of zero they start on [rad]: the controller's clearance pushes them out of
#: their singular zones on their own side, so the arm never turns to the other branch on its own.
KEEP_SIDE_RAD = 1e-3
#: The elbow (A4, 0-based 3): its angle follows from the pad pose alone, so the room it keeps is no branch's merit.
ELBOW = 3


def follow(model: RobotModel, q0: np.ndarray, points_m: list[np.ndarray], R: np.ndarray,
           zones: ClearanceZones) -> np.ndarray:
    """(k, n) [rad] the arm's configurations as the pad (orientation ``R`` (3, 3), world) moves in straight lines
    from where it is at ``q0`` (n,) [rad] through each of ``points_m`` (each (3,) [m, world]) in turn, the
    clearance's gradient descended in the nullspace (joint positions are not clipped: a configuration beyond a
    limit shows as negative room)."""
    m, data = model.model, model.model.createData()
    q = np.asarray(q0, float).copy()
    pin.framesForwardKinematics(m, data, q)
    here = data.oMf[model.tcp_id].translation.copy()
    lo, hi = model.limits.q_min, model.limits.q_max
    eye = np.eye(model.nq)
    out = []
    for point in points_m:
        n_steps = max(1, int(np.ceil(np.linalg.norm(point - here) / STEP_M)))
        for s in range(1, n_steps + 1):
            target = pin.SE3(R, here + (point - here) * (s / n_steps))
            for _ in range(ITER_PER_STEP):
                pin.computeJointJacobians(m, data, q)
                pin.updateFramePlacements(m, data)
                now = data.oMf[model.tcp_id]
                err = np.concatenate([target.translation - now.translation,
                                      pin.log3(target.rotation @ now.rotation.T)])
                J = pin.getFrameJacobian(m, data, model.tcp_id, pin.LOCAL_WORLD_ALIGNED)
                J_pinv = J.T @ np.linalg.inv(J @ J.T + 1e-4 * np.eye(6))
                push = -(eye - J_pinv @ J) @ clearance_gradient(q, lo, hi, zones)
                step = np.clip(J_pinv @ err + push, -STEP_RAD, STEP_RAD)
                side = np.where(q >= 0.0, 1.0, -1.0)
                q = q + step
                np.copyto(q, side * KEEP_SIDE_RAD, where=(zones.singular > 0.0) & (q * side < KEEP_SIDE_RAD))
            out.append(q.copy())
        here = np.asarray(point, float)
    return np.array(out)


def branch_room_rad(model: RobotModel, q0: np.ndarray, points_m: list[np.ndarray], R: np.ndarray,
                    zones: ClearanceZones) -> float:
    """The least room [rad] any joint but the elbow keeps to its position limit while the pad goes from ``q0``'s
    pose through ``points_m`` (:func:`follow`); negative: a joint would pass its limit."""
    return room_along_rad(model, follow(model, q0, points_m, R, zones))


def room_along_rad(model: RobotModel, qs: np.ndarray) -> float:
    """The least room [rad] any joint but the elbow keeps to its position limit over the configurations ``qs``
    (k, n) [rad] (:func:`follow`'s); negative: a joint past its limit."""
    room = np.minimum(model.limits.q_max - qs, qs - model.limits.q_min)
    room[:, ELBOW] = np.inf
    return float(room.min())


#: The zones :func:`follow` descends out of: the controller's clearance as ``controller.params.LimitParams`` sets it
#: by default (0.5 rad before each limit, 0.6 rad about zero on A2, A4 and A6; a test holds them equal).
CONTROLLER_ZONES = ClearanceZones(0.5, np.array([0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0]), 0.6)
#: A start whose arm keeps at least this room [rad] over the board is kept: the controller's last-line joint margin
#: (``LimitParams.joint_margin_rad``, 0.12 rad) and as much again.
ENOUGH_ROOM_RAD = 0.24
#: Rows of the raster the pad follows over the stain region (it goes from end to end along each in turn).
RASTER_ROWS = 5


def raster(lo_m: np.ndarray, hi_m: np.ndarray, rows: int = RASTER_ROWS) -> list[np.ndarray]:
    """The turning points (2,) [m, board frame] of a zig-zag over the rectangle ``lo_m``-``hi_m``: its centre first,
    then ``rows`` rows from end to end, alternately."""
    points = [(np.asarray(lo_m, float) + hi_m) / 2.0]
    for i, y in enumerate(np.linspace(lo_m[1], hi_m[1], rows)):
        ends = (lo_m[0], hi_m[0]) if i % 2 == 0 else (hi_m[0], lo_m[0])
        points += [np.array([ends[0], y]), np.array([ends[1], y])]
    return points


def candidate_seeds(azimuth_rad: float, q_seed: np.ndarray) -> list[np.ndarray]:
    """Seeds (n,) [rad] for the start pose's inverse kinematics over the arm's branches: ``q_seed`` with A1 at the
    pad's ``azimuth_rad`` (about the base's z axis) and a quarter, a half and three quarters of a turn from it
    (wrapped into +-pi), A2 at +-0.6 and +-1.2 rad, A6 at +-0.8 rad."""
    seeds = []
    for turn in (0.0, 0.5, 1.0, 1.5):
        a1 = (azimuth_rad + turn * np.pi + np.pi) % (2.0 * np.pi) - np.pi
        for a2 in (0.6, -0.6, 1.2, -1.2):
            for a6 in (0.8, -0.8):
                q = np.array(q_seed, float)
                q[0], q[1], q[5] = a1, a2, a6
                seeds.append(q)
    return seeds
