"""The board's surface learnt from the pad's touches (controller/surface_touch.py): a board seen behind its surface,
as perception sees a board whose size it measured too large, is met at the creep speed on the first approach and
its later approaches find it where it is (real PyBullet, real Pinocchio, the controller core in lock-step)."""

from __future__ import annotations

import numpy as np
import pytest

from controller.core import ControllerCore
from controller.executor_types import BoardPose
from controller.params import ControllerParams
from controller.surface_touch import SurfaceTouch
from interfaces.messages import Phase
from lampskit.core.planner_types import Stain
from sim.core import SimCore
from sim.params import SimParams

from .core_ticks import tick

DT = 0.001


def _board(offset_m: float = 0.0) -> BoardPose:
    R = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return BoardPose(R, np.array([0.68, 0.4, 0.25]) + offset_m * R[:, 2], np.array([0.8, 0.6]))


def test_a_touch_moves_the_board_along_its_normal_and_a_new_board_forgets_it():
    touch, seen = SurfaceTouch(max_offset_m=0.05), _board(-0.018)
    assert touch.untouched and touch.shifted(seen) is seen
    used = touch.touched(seen, 0.0175)  # the pad met the surface 17.5 mm above the seen board
    assert not touch.untouched and touch.offset_m == pytest.approx(0.0175)
    assert np.allclose(used.origin_m, _board(-0.0005).origin_m) and np.allclose(used.R, seen.R)
    again = touch.shifted(_board(-0.018))  # the next report of the same seen pose lands where the touch said
    assert np.allclose(again.origin_m, used.origin_m)
    used = touch.touched(used, 0.0004)  # a second touch refines it
    assert touch.offset_m == pytest.approx(0.0179) and touch.touches == 2
    assert np.allclose(touch.forget(used).origin_m, _board(-0.018).origin_m) and touch.untouched
    assert touch.touched(seen, 0.2) is seen and touch.refused == 1 and touch.untouched, "not a pose error: refused"


def _run(params: dict, seen_offset_m: float, ticks: int = 40_000) -> tuple[float, ControllerCore, int]:
    """The default wall board seen ``seen_offset_m`` along its normal from where it is; the skill wipes its three
    stains. Returns (the largest true contact force [N], the core, stains cleaned)."""
    core = ControllerCore(ControllerParams.from_table(params), _skill())
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}))
    worst = 0.0
    try:
        T = sim.board.T_board_to_world.copy()
        T[:3, 3] += seen_offset_m * T[:3, 2]
        seen = BoardPose.from_transform(T, sim.board.size_m)
        for n in range(ticks):
            if n % 100 == 0:
                core.executor.set_stains(seen, [Stain(s.id, np.array(s.centre_m), s.size_m, kappa=bool(r <= 0.03))
                                                for s, r in zip(sim.dirt.stains, sim.dirt.remaining())])
            o = sim.out
            tau = tick(core, o.q, o.dq, o.wrench, True, DT)
            sim.step(tau.copy())
            worst = max(worst, sim.take_peak_force_n())  # the true normal force over every physics step
            if core.executor.phase in (Phase.DONE, Phase.FAULT):
                break
        cleaned = int(sum(r <= 0.03 for r in sim.dirt.remaining()))
    finally:
        sim.close()
    return worst, core, cleaned


_SKILL = []


def _skill():
    if not _SKILL:
        from lampskit.learn.learn import bundled_skill
        _SKILL.append(bundled_skill())
    return _SKILL[0]


@pytest.mark.slow
def test_a_board_seen_20_mm_behind_its_surface_is_met_gently_and_then_found_where_it_is():
    worst, core, cleaned = _run({}, -0.02)
    ex = core.executor
    assert ex.phase == Phase.DONE and cleaned == 3, (ex.phase, ex.reason, cleaned)
    assert ex.surface.offset_m == pytest.approx(0.02, abs=0.002), ex.surface.offset_m
    assert ex.counters["surface_touches"] >= 1
    assert worst < 20.0, f"the pad met the board at {worst:.1f} N"
    # the same board with the first touch not slowed for: the fast descent meets the surface 4 mm early
    worst_fast, _, _ = _run({"executor": {"first_creep_height_m": 0.016}}, -0.02)
    assert worst_fast > worst + 5.0, (worst_fast, worst)
