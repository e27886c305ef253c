"""The whole default skill in process (PyBullet arm, Pinocchio controller, no network): joint speeds stay bounded."""

from __future__ import annotations

import numpy as np
import pytest

from arm.robot_model import RobotModel
from controller.core import TRACE_COLUMNS, ControllerCore
from controller.executor_types import BoardPose
from controller.params import ControllerParams
from lampskit.core.planner_types import Stain
from robot.lbr.params import LbrParams
from sim.core import SimCore
from sim.params import SimParams

from .core_ticks import tick


def _feed_stains(core: ControllerCore, sim: SimCore) -> None:
    board = BoardPose.from_transform(sim.board.T_board_to_world, sim.board.size_m)
    stains = [Stain(s.id, np.array(s.centre_m), s.size_m, kappa=bool(r <= 0.03))
              for s, r in zip(sim.dirt.stains, sim.dirt.remaining())]
    core.executor.set_stains(board, stains)


def _run(learned_skill, limits: dict, planner: dict | None = None) -> tuple[ControllerCore, np.ndarray, np.ndarray]:
    """(controller, remaining dirt per stain, peak |dq| / dq_max per joint) of one gravity-compensated run."""
    params = ControllerParams.from_table({"trace_ticks": 30_000, "limits": limits, "planner": planner or {}})
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}))
    core = ControllerCore(params, learned_skill)
    dq_max = RobotModel().limits.dq_max
    peak = np.zeros(7)
    try:
        for n in range(30_000):
            if n % 100 == 0:
                _feed_stains(core, sim)
            o = sim.out
            tau = tick(core, o.q, o.dq, o.wrench, True, 0.001)
            sim.step(tau.copy())
            np.maximum(peak, np.abs(sim.out.dq) / dq_max, out=peak)
            if core.executor.phase == "DONE":
                break
        remaining = sim.dirt.remaining()
    finally:
        sim.close()
    return core, remaining, peak


@pytest.mark.slow
def test_the_default_skill_keeps_every_joint_below_the_real_robot_adapters_speed_guard(learned_skill):
    """Planned without kinematic bounds the transitions ask for up to 0.64 m/s at the pad; unscaled, that drives
    joint A3 to ~0.9 of its speed limit, which the lbr adapter's guard (0.8) refuses. The planner's bounds and the
    speed override (it slows the skill where it would ask a joint for more than 0.6 of its limit, without
    stopping it) keep every joint below the guard, and the board is still cleaned."""
    guard = LbrParams().max_joint_speed_scale
    loose = {"max_speed_m_s": 2.0, "max_accel_m_s2": 50.0, "max_jerk_m_s3": 5000.0}
    _, _, unbounded = _run(learned_skill, {"reference_joint_speed_share": 10.0, "joint_speed_brake_1_s": 0.0}, loose)
    assert unbounded.max() > guard, f"the baseline without bounds, override and brake: {np.round(unbounded, 2)}"
    core, remaining, peak = _run(learned_skill, {})
    assert core.executor.phase == "DONE", core.executor.reason
    assert max(remaining) < 0.05, remaining
    assert peak.max() < guard - 0.05, f"joint speeds / limits {np.round(peak, 2)} (the adapter trips at {guard})"
    scale = core.trace.array()[:, TRACE_COLUMNS.index("speed_scale")]
    assert scale.min() < 0.9 and core.override.slowed_ticks > 0, "the override did act"
    assert scale.min() >= core.override.min_scale
