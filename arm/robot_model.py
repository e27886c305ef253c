"""Kinematics and dynamics of the described arm with Pinocchio (same URDF as the sim).

Used by the controller, by test clients (gravity compensation) and by the sim
to place the arm at a start pose facing the board and to drive its joints.
Joint vectors are (7,) [rad]; poses are in the world (robot base) frame.
The model carries the joints' rotor inertia in ``model.armature`` (so
``crba`` and ``computeMinverse`` give M + diag(Ia)) and their friction in
``model.damping`` (viscous) and ``model.friction`` (Coulomb), from
:mod:`.joint_dynamics`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from interfaces.errors import InterfaceError

from .description import TCP_FRAME, URDF_PATH
from .joint_dynamics import JointDynamics


class IkError(InterfaceError):
    """No joint configuration reaches the asked pose within the limits."""


@dataclass(frozen=True)
class JointLimits:
    """Limits from the description: position [rad], speed [rad/s], torque [Nm], each (7,)."""

    q_min: np.ndarray
    q_max: np.ndarray
    dq_max: np.ndarray
    tau_max: np.ndarray


class RobotModel:
    """Pinocchio model and data of the arm; one instance per thread (the data is scratch space).

    joints : rotor inertia and friction per joint (default: the cited iiwa figures of
    :mod:`.joint_dynamics`); kept as :attr:`joints` for a simulator that should match.
    """

    def __init__(self, urdf_path=URDF_PATH, joints: JointDynamics | None = None) -> None:
        self.model = pin.buildModelFromUrdf(str(urdf_path))
        self.joints = joints or JointDynamics()
        self.model.armature[:] = self.joints.armature_kg_m2
        self.model.damping[:] = self.joints.viscous_nm_s_rad
        self.model.friction[:] = self.joints.coulomb_nm
        self.data = self.model.createData()
        self.tcp_id = self.model.getFrameId(TCP_FRAME)
        self.nq = self.model.nq
        m = self.model
        self.limits = JointLimits(m.lowerPositionLimit.copy(), m.upperPositionLimit.copy(),
                                  m.velocityLimit.copy(), m.effortLimit.copy())

    def tcp_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(p (3,) [m], R (3, 3))`` of the pad centre in the world frame."""
        pin.framesForwardKinematics(self.model, self.data, q)
        oMf = self.data.oMf[self.tcp_id]
        return oMf.translation.copy(), oMf.rotation.copy()

    def tcp_jacobian(self, q: np.ndarray) -> np.ndarray:
        """(6, 7) Jacobian of the pad centre, linear rows first, world-aligned axes."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return pin.getFrameJacobian(self.model, self.data, self.tcp_id, pin.LOCAL_WORLD_ALIGNED)

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """(7,) joint torques [Nm] that hold the arm (and eraser) still against gravity."""
        return pin.computeGeneralizedGravity(self.model, self.data, q).copy()

    def solve_ik(self, p_target: np.ndarray, R_target: np.ndarray, q_init: np.ndarray,
                 tol_m: float = 1e-4, max_iter: int = 500) -> np.ndarray:
        """Joint positions putting the pad centre at ``p_target`` with orientation ``R_target``.

        Damped least squares on the 6-D pose error with a nullspace pull
        towards ``q_init`` (the arm's redundancy keeps a posture near the
        seed), steps clipped to the joint limits (kept 0.05 rad inside
        them). Raises :class:`IkError` if the pose is not reached to
        ``tol_m`` (and 1e-3 rad).
        """
        lo, hi = self.limits.q_min + 0.05, self.limits.q_max - 0.05
        q_rest = np.clip(np.asarray(q_init, float), lo, hi)
        q = q_rest.copy()
        target = pin.SE3(np.asarray(R_target, float), np.asarray(p_target, float))
        err = np.full(6, np.inf)
        for _ in range(max_iter):
            pin.framesForwardKinematics(self.model, self.data, q)
            current = self.data.oMf[self.tcp_id]
            err = np.concatenate([target.translation - current.translation,
                                  pin.log3(target.rotation @ current.rotation.T)])
            if np.linalg.norm(err[:3]) < tol_m and np.linalg.norm(err[3:]) < 1e-3:
                return q
            J = self.tcp_jacobian(q)
            J_pinv = J.T @ np.linalg.inv(J @ J.T + 1e-4 * np.eye(6))
            dq = J_pinv @ err + 0.1 * (np.eye(self.nq) - J_pinv @ J) @ (q_rest - q)
            q = np.clip(q + np.clip(dq, -0.2, 0.2), lo, hi)
        raise IkError(f"pose {np.round(p_target, 3).tolist()} not reached within the joint limits "
                      f"(position error {np.linalg.norm(err[:3]) * 1000:.1f} mm, "
                      f"orientation error {np.degrees(np.linalg.norm(err[3:])):.1f} deg)")
