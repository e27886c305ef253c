"""The arm's rest posture planned from where it stands: the same pad pose, its joints out of their clearance zones.

A 7-joint arm holds a pad pose along a one-parameter self-motion (the
elbow's swing). The controller's nullspace posture pulls towards a rest pose
and its clearance (:func:`controller.control.limits.clearance_torque`)
pushes each joint out of a zone before its position limit and each of the
shoulder's, elbow's and wrist's singular joints (A2, A4, A6) out of a zone
around zero. With the first state as the rest pose, an arm that starts with
A2 or A6 inside its zone has the two pulling against each other, and the
clearance wins along whatever direction the swing takes first: on random
board 322 it carried A1 from 0.5 rad onto its limit at 2.9 rad (A2 near zero
lines A1 and A3 up: a small change of A2 turns them by a lot), and the arm
pressed at its limit with the pad 40 mm off its reference; on board 245 A7
went onto its limit so.

:func:`planned_rest_posture` follows the self-motion from the first state
down the clearance's own potential (half the squared depth into each zone,
the quantity whose gradient the clearance pushes with), holding the pad
pose: the rest pose it returns is the nearest one on the same branch (the
signs of A2 and A6 kept) where the clearance has nothing left to push, or
as little as that branch allows. Pure maths on a private Pinocchio data
object: safe to run on the planner thread while the tick uses the model's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .robot_model import RobotModel

#: Largest joint step per iteration [rad]: small against the zones (0.5-0.6 rad), so the descent follows the
#: self-motion instead of jumping across a singular pose.
STEP_RAD = 0.02
#: Most iterations (each one forward kinematics and a Jacobian, about 30 us): a swing of up to 4 rad.
MAX_ITER = 600
#: The descent has arrived when the nullspace gradient's step is below this [rad].
DONE_RAD = 1e-4
#: The planned pose must hold the pad within this of where it was [m] (and 1e-3 rad), or the plan is dropped.
POSE_TOL_M = 1e-3


@dataclass(frozen=True)
class ClearanceZones:
    """The zones the clearance pushes joints out of, as :class:`controller.params.LimitParams` sets them.

    limit_zone_rad : before each position limit [rad]; singular (n,) 1.0 on the joints whose zero stretches the
    arm; singular_rad : around zero on those [rad].
    """

    limit_zone_rad: float
    singular: np.ndarray
    singular_rad: float


def clearance_gradient(q: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, zones: ClearanceZones) -> np.ndarray:
    """(n,) gradient of the clearance's potential at ``q`` (n,) [rad]: half the squared depth into each zone
    (limits ``q_min``, ``q_max`` (n,) [rad]); a singular joint at exactly zero is pushed to the positive side,
    as the clearance pushes it."""
    z = zones.limit_zone_rad
    g = np.maximum(q - (q_max - z), 0.0) - np.maximum(q_min + z - q, 0.0)
    depth = np.maximum(zones.singular_rad - np.abs(q), 0.0) * zones.singular
    return g - np.where(q >= 0.0, 1.0, -1.0) * depth


def clearance_potential(q: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, zones: ClearanceZones) -> float:
    """The potential of :func:`clearance_gradient` [rad^2]: 0 where every joint is out of every zone."""
    z = zones.limit_zone_rad
    lim = np.maximum(q - (q_max - z), 0.0) ** 2 + np.maximum(q_min + z - q, 0.0) ** 2
    sing = (np.maximum(zones.singular_rad - np.abs(q), 0.0) * zones.singular) ** 2
    return 0.5 * float(np.sum(lim) + np.sum(sing))


def planned_rest_posture(model: RobotModel, q0: np.ndarray, zones: ClearanceZones) -> np.ndarray:
    """(n,) [rad] the rest posture for an arm standing at ``q0`` (n,): the pad pose of ``q0`` held, the joints
    moved along the self-motion down :func:`clearance_potential` (damped least squares on the pose error, the
    potential's gradient projected into the Jacobian's nullspace, steps of at most :data:`STEP_RAD`). Returns a
    copy of ``q0`` when it already has no potential, or when the descent leaves the pose or the limits (it
    never should: the plan is then no better than standing still)."""
    q0 = np.asarray(q0, float)
    lo, hi = model.limits.q_min, model.limits.q_max
    if clearance_potential(q0, lo, hi, zones) == 0.0:
        return q0.copy()
    m, data = model.model, model.model.createData()
    pin.framesForwardKinematics(m, data, q0)
    target = pin.SE3(data.oMf[model.tcp_id])
    q = q0.copy()
    eye = np.eye(model.nq)
    for _ in range(MAX_ITER):
        pin.computeJointJacobians(m, data, q)
        pin.updateFramePlacements(m, data)
        now = data.oMf[model.tcp_id]
        err = np.concatenate([target.translation - now.translation, pin.log3(target.rotation @ now.rotation.T)])
        J = pin.getFrameJacobian(m, data, model.tcp_id, pin.LOCAL_WORLD_ALIGNED)
        J_pinv = J.T @ np.linalg.inv(J @ J.T + 1e-6 * np.eye(6))
        push = -(eye - J_pinv @ J) @ clearance_gradient(q, lo, hi, zones)
        step = J_pinv @ err + push
        q += np.clip(step, -STEP_RAD, STEP_RAD)
        if float(np.max(np.abs(push))) < DONE_RAD and float(np.linalg.norm(err[:3])) < 0.1 * POSE_TOL_M:
            break
    p, R = _pose(model, data, q)
    held = np.linalg.norm(p - target.translation) < POSE_TOL_M and \
        np.linalg.norm(pin.log3(target.rotation @ R.T)) < 1e-3
    if not held or np.any(q < lo) or np.any(q > hi) or \
            clearance_potential(q, lo, hi, zones) >= clearance_potential(q0, lo, hi, zones):
        return q0.copy()
    return q


def _pose(model: RobotModel, data: pin.Data, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pin.framesForwardKinematics(model.model, data, q)
    oMf = data.oMf[model.tcp_id]
    return oMf.translation.copy(), oMf.rotation.copy()
