"""The survey's second look: a board whose only stain the arm hid at the survey point.

Random board 456 (``lamps campaign --no-network --boards random --seeds 456``, one stain): the survey's point
put the pad 40 mm above the stain, and the pad and the wrist hid it from the camera; with no stain seen the
controller went DONE at 0 %. With nothing seen, the survey now looks again from the point that hides the fewest of
the board points the first one hid (:func:`controller.look_points.resurvey_point`).
"""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest

from controller.executor_types import BoardPose
from controller.look_points import resurvey_point, stain_targets, survey_hidden, survey_point
from controller.params import ExecutorParams
from launch.campaign import cell_stains
from launch.campaign_cells import Cell
from sim.board import board_from_params
from sim.board_sampler import sample_board
from sim.core import make_stains
from sim.params import SimParams

from .test_silhouette import STANDOFF_M, Scene

SEED = 456


@pytest.fixture(scope="module")
def scene():
    s = Scene(SEED)
    yield s
    pb.disconnect(s.client)


def _the_stain(scene: Scene) -> np.ndarray:
    """(9, 2) the centre and rim [m] of the cell's one stain (the sim's own generator, as the cell's)."""
    params = SimParams.from_table({"seed": SEED, "dirt": {"stains": 1}, "board": sample_board(SEED).table})
    (stain,) = make_stains(params, board_from_params(params.board))
    return stain_targets([np.asarray(stain.centre_m, float)], [float(stain.size_m)])


def test_the_cells_stain_is_the_campaigns(scene):
    _, centres = cell_stains(Cell(seed=SEED, stains=1, board=f"random:{SEED}"), sample_board(SEED).table)
    np.testing.assert_allclose(_the_stain(scene)[0], centres[0])


def test_the_second_look_sees_the_stain_the_survey_point_hid(scene):
    """At the survey point the rendered arm hides the stain (the case); the second point is elsewhere, hides fewer
    of the board points the first hid, and none of the stain."""
    p = ExecutorParams()
    first = survey_point(scene.board, p.look_clearance_m, scene.arm, STANDOFF_M)
    stain = _the_stain(scene)
    assert scene.rendered_hidden(scene.q_at(first), stain).any(), first
    hid = survey_hidden(scene.board, first, scene.arm, STANDOFF_M)
    assert len(hid) > 0
    again = resurvey_point(scene.board, first, scene.arm, STANDOFF_M)
    assert again is not None and np.linalg.norm(again - first) > 0.03, (first, again)
    assert not scene.rendered_hidden(scene.q_at(again), stain).any(), again
    assert scene.model_hidden(again, hid).sum() < len(hid)


def test_no_second_look_without_the_camera_or_the_arm(scene):
    blind = BoardPose(scene.board.R, scene.board.origin_m, scene.board.size_m)
    first = survey_point(scene.board, ExecutorParams().look_clearance_m, scene.arm, STANDOFF_M)
    assert resurvey_point(blind, first, scene.arm, STANDOFF_M) is None
    assert resurvey_point(scene.board, first, None, STANDOFF_M) is None


@pytest.mark.slow
def test_random_board_456_finds_its_only_stain_and_cleans_it(tmp_path):
    """The cell itself (``lamps up --no-network --board random:456 --stains 1``): the survey looks twice, the stain
    is wiped."""
    from .test_arm_clearance import run_random_board

    report, stdout, _ = run_random_board(tmp_path, SEED, 1)
    assert report["outcome"] == "cleaned", (report["outcome"], report.get("final_reason"), stdout[-3000:])
    assert report["dirt_removed_fraction"] >= 0.98 and not report["faults"], report["faults"]
    assert report["counters"]["controller"]["surveys_again"] == 1, report["counters"]["controller"]
