"""How far the arm's elbow is from folding against its limit at a pad pose (pure maths, a few vector operations).

On a 7-joint arm with a spherical shoulder (A1-A3) and wrist (A5-A7), the
elbow angle A4 follows from one distance alone: shoulder centre to wrist
centre, ``d^2 = a^2 + b^2 + 2 a b cos(q4)`` (``a``, ``b`` the upper arm and
forearm). The wrist centre is rigid in the pad frame (it lies on the last
joint's axis), so for a pad pose ``(p, R)`` it is ``p + R w``. A pose too close
to the shoulder folds the elbow past its limit: no joint configuration
reaches it, whatever the redundancy. The executor keeps its look points
(where the pad waits so the camera sees the board) where the elbow has
room, instead of commanding a pose the arm cannot take (on the table and the
tilted board the near edge was out of reach: the pad dipped into the board
at 30 N during the survey).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ArmReach:
    """The arm's elbow geometry; poses in the world (robot base) frame [m].

    shoulder_m : (3,) shoulder centre (fixed); wrist_in_pad_m : (3,) wrist centre in the pad frame;
    upper_m, fore_m : shoulder-elbow and elbow-wrist lengths; q4_max_rad : the elbow's limit (symmetric).
    """

    shoulder_m: np.ndarray
    wrist_in_pad_m: np.ndarray
    upper_m: float
    fore_m: float
    q4_max_rad: float

    def elbow_rad(self, p_m: np.ndarray, R: np.ndarray) -> float:
        """|q4| [rad] of any configuration putting the pad at ``p_m`` (3,) with orientation ``R`` (3, 3);
        inf beyond the stretched arm."""
        d = float(np.linalg.norm(p_m + R @ self.wrist_in_pad_m - self.shoulder_m))
        a, b = self.upper_m, self.fore_m
        c = (d * d - a * a - b * b) / (2.0 * a * b)
        return math.inf if c > 1.0 else math.acos(max(c, -1.0))

    def elbow_room_rad(self, p_m: np.ndarray, R: np.ndarray) -> float:
        """How far [rad] the elbow stays from its limit at that pad pose (negative: out of reach)."""
        return self.q4_max_rad - self.elbow_rad(p_m, R)


def arm_reach(model) -> ArmReach:
    """The :class:`ArmReach` of a :class:`~arm.robot_model.RobotModel` (its joints 2, 4 and 6 are the
    shoulder, elbow and wrist centres), from its kinematics at zero."""
    import pinocchio as pin

    q = np.zeros(model.nq)
    pin.forwardKinematics(model.model, model.data, q)
    pin.updateFramePlacements(model.model, model.data)
    joints = model.data.oMi
    shoulder, elbow, wrist = (joints[i].translation.copy() for i in (2, 4, 6))
    tcp = model.data.oMf[model.tcp_id]
    return ArmReach(shoulder_m=shoulder, wrist_in_pad_m=tcp.rotation.T @ (wrist - tcp.translation),
                    upper_m=float(np.linalg.norm(elbow - shoulder)), fore_m=float(np.linalg.norm(wrist - elbow)),
                    q4_max_rad=float(model.limits.q_max[3]))
