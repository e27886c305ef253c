"""The executor against a board pose that jumps and a pad that presses where the board model says it is in the air.

A valid stains stream that placed the board 10 m away was adopted while DONE: the controller re-approached,
pressed the real board to the force cap and, once faulted, kept pressing (the lift went by the wrong board).
Here, with the ideal arm of the unit tests: a board out of reach is refused; a jump is never adopted at once
(lifted off first when pressing), only after it held still ``board_confirm_s`` in the air, and then surveyed;
a pad found pressing while held in the air is lifted by what is measured, and ``pad_down`` counts the measured
force, so a controller that exits waits for it.
"""

from __future__ import annotations

import numpy as np
import pytest

from controller.executor import SkillExecutor
from controller.executor_stage import RELEASED_N
from controller.executor_types import BoardPose
from controller.params import ExecutorParams

from .test_controller_units import BOARD, WALL, IdealArm, RaisedBoardArm, phases, run, stains


def _at(board: BoardPose | None, seen: BoardPose) -> bool:
    """``board`` is the pose ``seen`` (within the millimetre a touch of the board moves it along its normal:
    controller/surface_touch.py)."""
    return board is not None and board.close_to(seen, tol_m=1e-3, tol_rad=1e-9)


def _shifted(dx_m: float) -> BoardPose:
    return BoardPose(WALL, BOARD.origin_m + np.array([0.0, dx_m, 0.0]), BOARD.size_m)


@pytest.mark.attack('3', "a board placed out of the arm's reach",
                    'refused, nothing starts')
def test_a_board_out_of_reach_is_refused_and_nothing_starts(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams())
    far = BoardPose(WALL, np.array([10.0, 0.4, 0.25]), BOARD.size_m)
    ex.set_stains(far, stains())
    assert ex.board is None and ex.counters["boards_out_of_reach"] == 1 and "beyond its reach" in ex.board_note
    ex.wait()
    assert ex.phase == "WAIT_PEERS"


@pytest.mark.attack('3', 'a board pose that jumps 0.30 m while wiping',
                    'lifted off first; adopted only after it held still 2 s, then surveyed')
def test_a_jump_while_wiping_lifts_off_and_is_not_adopted_until_it_held_still(learned_skill):
    p = ExecutorParams(board_confirm_s=4.0)
    ex = SkillExecutor(learned_skill, p)
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    run(ex, arm, 0.1)
    run(ex, arm, 12.0, on_tick=lambda k, e: e.set_stains(BOARD, stains()) if k % 50 == 0 else None)
    assert ex.phase in ("WIPE", "TRANSITION") and ex.motion.setpoint.contact, ex.phase
    jumped = _shifted(0.3)
    ex.set_stains(jumped, stains())
    assert ex.phase == "PAUSED" and "jumped 0.30 m" in ex.reason and _at(ex.board, BOARD)
    log = run(ex, arm, 3.0, on_tick=lambda k, e: e.set_stains(jumped, stains()) if k % 50 == 0 else None)
    assert not log[-1][5] and arm.tool.force_n == 0.0 and arm.tool.h >= p.standoff_m - 1e-6, "lifted off"
    assert _at(ex.board, BOARD) and ex.phase == "PAUSED", "not adopted within board_confirm_s"
    log = run(ex, arm, 2.0, on_tick=lambda k, e: e.set_stains(jumped, stains()) if k % 50 == 0 else None)
    assert _at(ex.board, jumped) and ex.counters["board_jumps_adopted"] == 1
    assert ex.counters["surveys"] == 2 and ex.current_mp == "survey", "the new pose surveyed before any approach"


def test_a_jump_that_goes_away_is_never_adopted_and_the_job_goes_on(learned_skill):
    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0))
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    run(ex, arm, 8.0)
    ex.set_stains(_shifted(0.5), stains())  # one spoofed report
    assert ex.phase == "PAUSED"
    log = run(ex, arm, 3.0, on_tick=lambda k, e: e.set_stains(BOARD, stains()) if k % 50 == 0 else None)
    assert _at(ex.board, BOARD) and ex.counters["board_jumps_back"] >= 1
    assert "WIPE" in phases(log) or "APPROACH" in phases(log), phases(log)


@pytest.mark.attack('3', 'a board pose that jumps while DONE (executor over real skills)',
                    'held, not approached')
def test_a_jump_while_done_is_held_not_approached(learned_skill):
    """The case that pressed the real board: a jump while DONE never leads to an approach of the new pose before
    it has held still and been surveyed."""
    ex = SkillExecutor(learned_skill, ExecutorParams(survey_s=0.0, board_confirm_s=5.0))
    arm = IdealArm()
    ex.set_stains(BOARD, [])
    run(ex, arm, 0.5)
    assert ex.phase == "DONE"
    jumped = _shifted(0.2)
    log = run(ex, arm, 3.0, on_tick=lambda k, e: e.set_stains(jumped, stains()) if k % 50 == 0 else None)
    assert set(phases(log)) <= {"DONE", "PAUSED"}, phases(log)
    assert max(e[7] for e in log) >= 0 and min(e[7] for e in log) > 0.0, "the pad never went down"
    assert _at(ex.board, BOARD)


@pytest.mark.attack('3', 'a pad that presses while the board model says it is held in the air',
                    'lifted by what is measured, force below 0.5 N')
def test_a_pad_pressing_while_held_in_the_air_is_lifted_and_counts_as_down(learned_skill):
    """The board model off: held in the air by the model, the pad presses in fact (10 N). pad_down says True by the
    measured force (a controller that exits waits for it), and the hold lifts the pad by what is measured."""
    p = ExecutorParams(survey_s=0.0)
    ex = SkillExecutor(learned_skill, p)
    arm = RaisedBoardArm(0.08 + 0.0005)  # the real surface 0.5 mm above the pad held at its start height
    ex.set_stains(BOARD, [])
    arm.follow(ex.step(0.001, arm.tool))
    assert arm.tool.force_n > RELEASED_N and not ex.motion.setpoint.contact
    ex.step(0.001, arm.tool)
    assert ex.pad_down, "the measured force counts"
    run(ex, arm, 1.0)
    assert arm.tool.force_n < RELEASED_N and not ex.pad_down, arm.tool.force_n
    assert ex.counters["lifts_from_a_pressing_hold"] >= 1 and ex.phase == "DONE"
