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

The shoulder and the wrist have singular poses too: A2 = 0 lines A1 and A3
up, A6 = 0 lines A5 and A7 up (the arm turns about one axis with two
joints, and the task loses a direction). Neither follows from the pad pose
alone: the elbow can swing on a circle about the shoulder-wrist line (the
arm's self-motion) and with it the upper arm and the forearm. Over that
circle ``|q2|``, the upper arm's angle from A1's axis, and ``|q6|``, the
forearm's angle from A7's, each span a range in closed form; a pose where
even the best swing leaves one of them near zero is wiped through the
singularity whatever the nullspace posture does (:meth:`ArmReach.shoulder_tilt_max_rad`,
:meth:`ArmReach.wrist_bend_range_rad`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: A pad pose that puts the elbow closer than this to stretched straight [rad] is out of reach: the pad would wipe
#: at the edge of the arm's workspace, through its singular pose.
UNREACHABLE_STRETCH_RAD = 0.1
#: A pad pose where even the elbow's best swing leaves A2 or A6 this close to zero [rad] is out of reach: two
#: joint axes lined up within 11 degrees, the arm at the shoulder's or the wrist's singularity whatever its
#: nullspace posture does (:meth:`ArmReach.shoulder_tilt_max_rad`, :meth:`ArmReach.wrist_bend_range_rad`).
UNREACHABLE_ALIGNED_RAD = 0.2


@dataclass(frozen=True)
class ArmReach:
    """The arm's elbow geometry; poses in the world (robot base) frame [m].

    shoulder_m : (3,) shoulder centre (fixed); wrist_in_pad_m : (3,) wrist centre in the pad frame;
    upper_m, fore_m : shoulder-elbow and elbow-wrist lengths; q4_max_rad : the elbow's limit (symmetric);
    axis1 : (3,) A1's axis, world (the shoulder's ``q2 = 0`` direction of the upper arm); axis7_in_pad : (3,)
    A7's axis in the pad frame, from the wrist centre outwards (the forearm's ``q6 = 0`` direction);
    q6_max_rad : the wrist's limit (symmetric).
    """

    shoulder_m: np.ndarray
    wrist_in_pad_m: np.ndarray
    upper_m: float
    fore_m: float
    q4_max_rad: float
    axis1: np.ndarray
    axis7_in_pad: np.ndarray
    q6_max_rad: float

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

    def _elbow_circle(self, p_m: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, float, float] | None:
        """The elbow's circle at that pad pose: (unit shoulder-to-wrist direction u (3,), the circle centre's
        distance from the shoulder along u [m], its radius [m]); None beyond the stretched arm."""
        sw = p_m + R @ self.wrist_in_pad_m - self.shoulder_m
        d = float(np.linalg.norm(sw))
        a, b = self.upper_m, self.fore_m
        if d <= 1e-9 or d > a + b:
            return None
        along = (a * a - b * b + d * d) / (2.0 * d)
        return sw / d, along, math.sqrt(max(a * a - along * along, 0.0))

    def shoulder_tilt_max_rad(self, p_m: np.ndarray, R: np.ndarray) -> float:
        """The largest ``|q2|`` [rad] over the elbow's swing at the pad pose ``p_m`` (3,), ``R`` (3, 3): the upper
        arm's largest angle from A1's axis (near 0: the wrist centre above the shoulder, A1 and A3 lined up
        whatever the elbow does); nan beyond the stretched arm."""
        circle = self._elbow_circle(p_m, R)
        if circle is None:
            return math.nan
        u, along, radius = circle
        par = float(u @ self.axis1)
        perp = math.sqrt(max(1.0 - par * par, 0.0))
        return math.acos(min(max((along * par - radius * perp) / self.upper_m, -1.0), 1.0))

    def wrist_bend_range_rad(self, p_m: np.ndarray, R: np.ndarray) -> tuple[float, float]:
        """The least and the largest ``|q6|`` [rad] over the elbow's swing at that pad pose: the forearm's angles
        from A7's axis (the largest near 0: A5 and A7 lined up whatever the elbow does; the least over the
        wrist's limit: the wrist cannot bend that far); (nan, nan) beyond the stretched arm."""
        circle = self._elbow_circle(p_m, R)
        if circle is None:
            return math.nan, math.nan
        u, along, radius = circle
        t = R @ self.axis7_in_pad
        d = float(np.linalg.norm(p_m + R @ self.wrist_in_pad_m - self.shoulder_m))
        par = float(u @ t)
        perp = math.sqrt(max(1.0 - par * par, 0.0))
        mid, swing = (d - along) * par / self.fore_m, radius * perp / self.fore_m
        return (math.acos(min(max(mid + swing, -1.0), 1.0)), math.acos(min(max(mid - swing, -1.0), 1.0)))


def arm_reach(model) -> ArmReach:
    """The :class:`ArmReach` of a :class:`~arm.robot_model.RobotModel` (its joints 2, 4 and 6 are the
    shoulder, elbow and wrist centres; each joint turns about its own z axis), from its kinematics at zero,
    where the arm stands straight up: the upper arm along A1's axis, the forearm along A7's."""
    import pinocchio as pin

    q = np.zeros(model.nq)
    pin.forwardKinematics(model.model, model.data, q)
    pin.updateFramePlacements(model.model, model.data)
    joints = model.data.oMi
    shoulder, elbow, wrist = (joints[i].translation.copy() for i in (2, 4, 6))
    tcp = model.data.oMf[model.tcp_id]
    return ArmReach(shoulder_m=shoulder, wrist_in_pad_m=tcp.rotation.T @ (wrist - tcp.translation),
                    upper_m=float(np.linalg.norm(elbow - shoulder)), fore_m=float(np.linalg.norm(wrist - elbow)),
                    q4_max_rad=float(model.limits.q_max[3]), axis1=joints[1].rotation[:, 2].copy(),
                    axis7_in_pad=tcp.rotation.T @ joints[7].rotation[:, 2], q6_max_rad=float(model.limits.q_max[5]))


def pad_reach_problem(arm: ArmReach, p_m: np.ndarray, R: np.ndarray) -> str | None:
    """Why the pad at ``p_m`` (3,) [m, world] with orientation ``R`` (3, 3) is beyond the arm (None: it is not): beyond
    the stretched arm, the elbow folded past its limit, the arm stretched straight (within
    :data:`UNREACHABLE_STRETCH_RAD` of A4 = 0), the wrist centre over the shoulder or the forearm along the pad's
    last axis at every swing of the elbow (A2 or A6 within :data:`UNREACHABLE_ALIGNED_RAD` of zero), or the wrist
    bent past its limit at every swing. The controller skips a stain with such a point; the random boards
    (:mod:`sim.board_sampler`) have none in their stain region."""
    d = float(np.linalg.norm(p_m))
    elbow = arm.elbow_rad(p_m, R)
    if not math.isfinite(elbow):
        return f"beyond the stretched arm ({d:.2f} m from the base)"
    if arm.elbow_room_rad(p_m, R) < 0.0:
        return f"too close to the shoulder: the elbow would fold past its limit ({d:.2f} m from the base)"
    if elbow < UNREACHABLE_STRETCH_RAD:
        return f"at the edge of the arm's reach: the elbow stretched to {elbow:.2f} rad ({d:.2f} m from the base)"
    shoulder = arm.shoulder_tilt_max_rad(p_m, R)
    if shoulder < UNREACHABLE_ALIGNED_RAD:
        return (f"over the shoulder: A2 within {shoulder:.2f} rad of zero at any swing of the elbow (A1 and A3 "
                f"lined up, {d:.2f} m from the base)")
    least, most = arm.wrist_bend_range_rad(p_m, R)
    if most < UNREACHABLE_ALIGNED_RAD:
        return (f"where the wrist stretches: A6 within {most:.2f} rad of zero at any swing of the elbow (A5 and A7 "
                f"lined up, {d:.2f} m from the base)")
    if least > arm.q6_max_rad:
        return f"where the wrist would bend past its limit: A6 at least {least:.2f} rad at any swing of the elbow"
    return None
