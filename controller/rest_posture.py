"""The nullspace posture's rest pose: the first state's, then carried at a bounded joint speed to the planned one.

The plan (:func:`arm.posture.planned_rest_posture`, some 600 forward
kinematics: 15-25 ms) runs off the tick (:class:`~controller.off_tick.OffTick`:
on the planner thread in real time, at once in lock-step). Until it answers
the rest pose is the first state, where the arm stands; then it moves towards
the plan at :attr:`RestPosture.rate_rad_s` on every joint, so the posture's
spring never jumps and the self-motion it drives stays slow (the swing to the
plan on random board 322 is 1.7 rad of A1: 7 s at 0.25 rad/s, while the pad
flies to its survey point).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from arm.posture import ClearanceZones, planned_rest_posture
from arm.robot_model import RobotModel

from .off_tick import OffTick
from .params import LimitParams


class RestPosture:
    """The rest pose ``q`` (n,) [rad] the posture spring pulls towards; None before the first state.

    Parameters
    ----------
    plan : the rest pose for an arm standing at ``q0`` (n,) [rad] (pure; None: the first state stays the rest).
    rate_rad_s : how fast each joint of the rest pose moves towards the plan [rad/s].

    Attributes
    ----------
    q : (n,) [rad] or None
    goal : (n,) [rad] or None
        The plan's answer, None while it runs (or without a plan).
    job : OffTick
        Where the plan runs; its ``executor`` is the planner thread in real time.
    """

    __slots__ = ("q", "goal", "job", "rate_rad_s", "_plan", "_way")

    def __init__(self, plan: Callable[[np.ndarray], np.ndarray] | None, rate_rad_s: float) -> None:
        if not rate_rad_s > 0.0:
            raise ValueError(f"the rest pose's rate must be > 0 rad/s, got {rate_rad_s}")
        self.q: np.ndarray | None = None
        self.goal: np.ndarray | None = None
        self.job = OffTick()
        self.rate_rad_s = float(rate_rad_s)
        self._plan = plan
        self._way: np.ndarray | None = None  # scratch: the step towards the goal

    def reset(self) -> None:
        """Forget the rest pose (a restart): the next state sets it again and plans anew."""
        self.q = self.goal = None
        self.job.drop()

    def begin(self, q: np.ndarray) -> None:
        """The first state ``q`` (n,) [rad]: the rest pose, and the plan started from it."""
        self.q = np.array(q, float)
        self.goal = None
        if self._plan is not None:
            q0, plan = self.q.copy(), self._plan
            self.job.start(lambda: plan(q0), self._take)

    def _take(self, goal: np.ndarray) -> None:
        if self.q is not None and goal.shape == self.q.shape and np.all(np.isfinite(goal)):
            self.goal = np.array(goal, float)
            self._way = np.empty_like(self.goal)

    def step(self, dt_s: float) -> None:
        """One tick of ``dt_s`` [s]: take the plan's answer when it is done, move the rest pose towards it (in
        place, no allocation)."""
        self.job.poll()
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
    return RestPosture(lambda q0: planned_rest_posture(model, q0, zones), rate)
