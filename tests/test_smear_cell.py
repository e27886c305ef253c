"""A smear is a state, end to end: a stain the eraser cannot lift (the sim's ``ghost``) is called smeared by
perception, the executor moves on after a pass of its own and the report names it.

The units: the sim's ghost floor, the stain book's rule (a smear report counts only after a pass of the
executor's), the report's naming. The cell: a real ``lamps sim`` with its camera, the controller on perception's
stains, perception with its smear watch, over Zenoh in lock-step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.stain_book import StainBook
from interfaces.errors import ConfigError
from lampskit.core.planner_types import Stain
from launch.report import stains_section, summary_lines
from perception.params import PerceptionParams
from sim.board import board_from_params
from sim.core import make_stains
from sim.dirt import DirtGrid, StainShape, stains_from_specs
from sim.params import SimParams

from .test_controller_service import ControllerThread
from .test_perception_service import PerceptionThread
from .zenoh_helpers import SimProcess, wait_for


def _wipe_all(g: DirtGrid, times: int) -> None:
    """The pad pressed at 10 N and slid over the whole grid ``times`` times."""
    for _ in range(times):
        for x in np.arange(0.0, 0.4, 0.01):
            g.wipe(np.array([x, 0.15]), np.array([1.0, 0.0]), (0.2, 0.2), np.array([0.25, 0.0]), 0.0, 10.0, 0.004,
                   2.0, 2.0)


def test_a_ghost_keeps_its_share_of_the_dirt_however_often_it_is_wiped():
    shapes = [StainShape(0, (0.1, 0.15), 0.06), StainShape(1, (0.3, 0.15), 0.06, ghost=0.4)]
    g = DirtGrid(np.array([0.4, 0.3]), 0.002, shapes, 0)
    _wipe_all(g, 3)
    first = g.remaining()
    _wipe_all(g, 30)
    left = g.remaining()
    assert left[0] < 0.01 and first[0] > left[0]  # a plain stain goes on getting cleaner
    assert left[1] == pytest.approx(0.4, abs=0.01) and 0.4 < first[1] < first[0] + 0.4  # down to its ghost
    plain = DirtGrid(np.array([0.4, 0.3]), 0.002, shapes[:1], 0)
    assert plain._floor is None  # no ghost: the plain wipe
    lo, hi = np.array([0.1, 0.1]), np.array([0.7, 0.5])
    assert stains_from_specs([{"centre_m": [0.3, 0.3], "size_m": 0.05, "ghost": 0.3}], lo, hi)[0].ghost == 0.3
    with pytest.raises(ConfigError, match="ghost must be in"):
        stains_from_specs([{"centre_m": [0.3, 0.3], "size_m": 0.05, "ghost": 1.0}], lo, hi)


def _stain(i: int, smeared: bool = False, kappa: bool = False, passes: int = 4) -> Stain:
    return Stain(i, np.array([0.1 + 0.2 * i, 0.2]), 0.05, kappa=kappa, smeared=smeared, remaining=0.4,
                 passes=passes)


def test_a_smear_closes_a_stain_only_once_perception_has_judged_a_pass_of_the_executors_own():
    """The arm passing over a stain on the way to another, or hiding it while it wipes a neighbour, makes no
    progress either: perception's smear report is taken only once perception has counted a pass after the
    executor's own pass over the stain ended (the stain back in view); then the stain is closed, not given up."""
    book = StainBook(recheck_s=1.0, max_passes=5)
    book.update([_stain(0, smeared=True), _stain(1)], 0.0)
    assert book.open_ids(0.0) == {0, 1} and not book.smeared  # no pass of ours over stain 0 yet
    assert not book.end_pass(0, 1.0)
    book.update([_stain(0, smeared=True), _stain(1)], 2.0)
    assert not book.smeared  # the smear of the 4 passes before ours: ours not judged yet (random board 322)
    book.update([_stain(0, smeared=True, passes=5), _stain(1)], 2.5)
    assert set(book.smeared) == {0} and book.smeared[0].remaining == 0.4 and book.smeared[0].passes == 5
    assert book.is_done(0) and not book.is_done(1)
    assert book.open_ids(5.0) == {1} and book.pending() == []
    # perception seeing progress again (not smeared) does not reopen it: the executor moved on
    book.update([_stain(0), _stain(1, kappa=True)], 6.0)
    assert book.open_ids(6.0) == set() and set(book.smeared) == {0}


def test_the_report_names_a_smeared_stain_with_its_remaining_and_passes():
    truth = [{"robot_time_ns": t, "centres_board_m": [[0.1, 0.2], [0.3, 0.2]], "sizes_m": [0.05, 0.05],
              "stain_ids": [0, 1], "remaining": r} for t, r in ((0, [1.0, 1.0]), (9_000_000_000, [0.01, 0.41]))]
    seen = [{"robot_time_ns": 5_000_000_000, "stains": [
        {"centre_board_m": [0.1, 0.2], "kappa": True, "smeared": False, "remaining": 0.0, "passes": 1},
        {"centre_board_m": [0.302, 0.2], "kappa": False, "smeared": True, "remaining": 0.43, "passes": 3}]}]
    stains = stains_section(truth, seen)
    assert stains[0]["smeared"] is None
    assert stains[1]["smeared"] == {"at_s": 5.0, "remaining": 0.43, "passes": 3}
    report = {"outcome": "incomplete", "dirt_removed_fraction": 0.8, "sim_time_s": 9.0, "duration_s": 12.0,
              "normal_force_mean_n": 10.0, "normal_force_std_n": 1.0, "max_normal_force_n": 14.0,
              "tracking_rms_m": 0.001, "max_junction_accel_jump": 0.0, "junction_step_ratio_max": 1.0,
              "stains": stains, "force_cap_n": 40.0, "faults": []}
    line = next(x for x in summary_lines(report) if x.startswith("  stain 1"))
    assert "smeared at 5.0 s (43% left after 3 passes)" in line, line
    # a recording of a perception without smears (no field) names none
    old = [{"robot_time_ns": 1, "stains": [{"centre_board_m": [0.3, 0.2], "kappa": False, "remaining": 0.4}]}]
    assert all(s["smeared"] is None for s in stains_section(truth, old))


def _ghost_specs(ghost_index: int, ghost: float) -> list[dict]:
    """The default cell's three stains (seed 0) as stain tables, stain ``ghost_index`` with a ghost."""
    params = SimParams()
    specs = []
    for s in make_stains(params, board_from_params(params.board)):
        specs.append({"centre_m": list(s.centre_m), "size_m": s.size_m, "aspect": s.aspect,
                      "angle_deg": math.degrees(s.angle_rad), "ghost": ghost if s.id == ghost_index else 0.0})
    return specs


@pytest.mark.slow
def test_a_cell_with_a_ghost_stain_calls_it_smeared_and_moves_on(tmp_path, learned_skill):
    """The controller on perception's stains over a board whose stain 1 keeps 45 % of its ink: perception calls
    it smeared after its passes without progress, the executor closes it after a pass of its own (not after
    ``max_passes``) and ends DONE; the other stains are wiped and judged clean."""
    ghost = 1
    sim_table = {"mode": "lockstep", "camera": {"rate_hz": 10.0}, "dirt": {"stain": _ghost_specs(ghost, 0.45)}}
    with SimProcess(tmp_path, sim_table) as sim, \
            ControllerThread(sim, learned_skill, {"stains_from": "perception", "trace_ticks": 0,
                                                  "executor": {"max_passes": 6}}) as ctl, \
            PerceptionThread(sim.robot_id, [sim.port, ctl.port], PerceptionParams()) as per:
        ctl.wait_phase(("WIPE",), 90.0)
        wait_for(lambda: ctl.phase == "DONE" and ctl.core.executor.book.smeared, 400.0,
                 "the controller DONE with a smeared stain")
        counters = dict(ctl.core.executor.counters)
        book = ctl.core.executor.book
        last = per.sent[-1][1]
    print(f"executor {counters}; smeared {book.smeared}; passes "
          f"{ {i: book.passes(i) for i in book.stains} }; last stains "
          f"{[(s.id, round(s.remaining, 2), s.kappa, s.smeared, s.passes) for s in last.stains]}")
    assert counters.get("stains_smeared") == 1, counters
    (sid, s), = book.smeared.items()
    assert 1 <= book.passes(sid) < 6 and s.remaining > 0.2
    others = [st for st in last.stains if st.id != sid]
    assert others and all(st.kappa for st in others), last.stains
