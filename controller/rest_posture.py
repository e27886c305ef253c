"""The nullspace posture's rest pose: the first state's, then carried at a bounded joint speed to the planned one.

The plan (:func:`arm.posture.planned_rest_posture`, some 600 forward
kinematics: 15-25 ms) runs off the tick (:class:`~controller.off_tick.OffTick`:
on the planner thread in real time, at once in lock-step). Until it answers
the rest pose is the first state, where the arm stands; then it moves towards
the plan at :attr:`RestPosture.rate_rad_s` on every joint, so the posture's
spring never jumps and the self-motion it drives stays slow (the swing to the
plan on random board 322 is 1.7 rad of A1: 7 s at 0.25 rad/s, while the pad
flies to its survey point).

A plan holds the pad pose it was made at. Where the pad goes next the same
joints may sit in a zone again (on random board 51 the planned wrist came
back to A6 = 0.01 over the first stain, and the pad touched the board with
the forearm along the normal: 21 N), so while the arm stands in a zone the
rest pose is planned again from where it stands, every
:attr:`RestPosture.replan_s` of robot time; out of every zone the last plan
stays (the posture keeps its anchor: the arm does not drift along its
self-motion).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from arm.posture import ClearanceZones, clearance_potential, planned_rest_posture
from arm.robot_model import RobotModel

from .off_tick import OffTick
from .params import LimitParams

#: The arm stands in a zone when the clearance's potential is above this [rad^2] (a joint 0.02 rad deep).
IN_ZONE_RAD2 = 2e-4


class RestPosture:
    """The rest pose ``q`` (n,) [rad] the posture spring pulls towards; None before the first state.

    Parameters
    ----------
    plan : the rest pose for an arm standing at ``q0`` (n,) [rad] (pure; None: the first state stays the rest).
    rate_rad_s : how fast each joint of the rest pose moves towards the plan [rad/s].
    in_zone : whether an arm at ``q`` (n,) [rad] stands in a zone the plan leaves (then it is planned again).
    replan_s : robot time between plans while the arm stands in a zone [s].

    Attributes
    ----------
    q : (n,) [rad] or None
    goal : (n,) [rad] or None
        The plan's answer, None while it runs (or without a plan).
    job : OffTick
        Where the plan runs; its ``executor`` is the planner thread in real time.
    plans, plans_in_zone : int
        Plans started, and of them those started again because the arm stood in a zone (the controller's status
        counters ``rest_posture_plans``, ``rest_posture_plans_in_zone``).
    """

    __slots__ = ("q", "goal", "job", "rate_rad_s", "replan_s", "plans", "plans_in_zone", "_plan", "_in_zone", "_way",
                 "_since_s")

    def __init__(self, plan: Callable[[np.ndarray], np.ndarray] | None, rate_rad_s: float,
                 in_zone: Callable[[np.ndarray], bool] | None = None, replan_s: float = 1.0) -> None:
        if not rate_rad_s > 0.0:
            raise ValueError(f"the rest pose's rate must be > 0 rad/s, got {rate_rad_s}")
        if not replan_s > 0.0:
            raise ValueError(f"the rest pose's re-plan period must be > 0 s, got {replan_s}")
        self.q: np.ndarray | None = None
        self.goal: np.ndarray | None = None
        self.job = OffTick()
        self.rate_rad_s = float(rate_rad_s)
        self.replan_s = float(replan_s)
        self.plans = self.plans_in_zone = 0
        self._plan = plan
        self._in_zone = in_zone
        self._way: np.ndarray | None = None  # scratch: the step towards the goal
        self._since_s = 0.0  # robot time since the last plan started

    def reset(self) -> None:
        """Forget the rest pose (a restart): the next state sets it again and plans anew."""
        self.q = self.goal = None
        self.job.drop()

    def begin(self, q: np.ndarray) -> None:
        """The first state ``q`` (n,) [rad]: the rest pose, and the plan started from it."""
        self.q = np.array(q, float)
        self.goal = None
        self._start(q)

    def _start(self, q: np.ndarray) -> None:
        self._since_s = 0.0
        if self._plan is not None:
            q0, plan = np.array(q, float), self._plan
            self.plans += 1
            self.job.start(lambda: plan(q0), self._take)

    def _take(self, goal: np.ndarray) -> None:
        if self.q is not None and goal.shape == self.q.shape and np.all(np.isfinite(goal)):
            self.goal = np.array(goal, float)
            self._way = np.empty_like(self.goal)

    def step(self, q_now: np.ndarray, dt_s: float) -> None:
        """One tick of ``dt_s`` [s] with the arm at ``q_now`` (n,) [rad]: take the plan's answer when it is done,
        plan again every :attr:`replan_s` while the arm stands in a zone, move the rest pose towards the plan (in
        place, no allocation but a plan's start)."""
        if self.job.poll() and self._in_zone is not None:
            self._since_s += dt_s
            if self._since_s >= self.replan_s and self.q is not None:
                self._since_s = 0.0
                if self._in_zone(q_now):
                    self.plans_in_zone += 1
                    self._start(q_now)
        q, goal, way = self.q, self.goal, self._way
        if q is None or goal is None or way is None:
            return
        d = self.rate_rad_s * dt_s
        np.subtract(goal, q, out=way)
        np.clip(way, -d, d, out=way)
        np.add(q, way, out=q)


def rest_posture_for(model: RobotModel, limits: LimitParams) -> RestPosture:
    """The :class:`RestPosture` of the controller's ``limits``: planned out of the clearance's own zones at
    ``rest_plan_rate_rad_s``; no plan when that is 0 or the clearance is off."""
    rate = limits.rest_plan_rate_rad_s
    if rate <= 0.0 or limits.clearance_stiffness_nm_rad <= 0.0:
        return RestPosture(None, 1.0)
    singular = np.zeros(model.nq)
    singular[[j - 1 for j in limits.singular_joints if j <= model.nq]] = 1.0
    zones = ClearanceZones(limits.clearance_zone_rad, singular, limits.singular_clearance_rad)
    lo, hi = model.limits.q_min, model.limits.q_max
    return RestPosture(lambda q0: planned_rest_posture(model, q0, zones), rate,
                       lambda q: clearance_potential(q, lo, hi, zones) > IN_ZONE_RAD2)
