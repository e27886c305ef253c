"""Random boards (sim/board_sampler.py): seeded and reproducible, spread over the workspace, each one a board the
simulator really starts on (real PyBullet), reachable by name from lamps up and lamps campaign."""

from __future__ import annotations

import json

import numpy as np
import pytest

from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from interfaces.transforms import matrix_from_quat_wxyz
from launch.campaign_cells import cells_of
from launch.cli import UpError, board_env
from sim.board import board_from_params
from sim.board_sampler import (
    MAX_STAINS,
    board_refusal,
    random_board_table,
    random_seed_of,
    rotation_from_angles,
    sample_board,
)
from sim.core import SimCore, make_stains
from sim.params import SimParams

SEEDS = range(12)


@pytest.fixture(scope="module")
def draws():
    model = RobotModel()
    return {s: sample_board(s, model) for s in SEEDS}


def test_a_seed_gives_the_same_board_every_time_and_seeds_differ(draws):
    again = sample_board(3)
    assert again.table == draws[3].table and again.refused == draws[3].refused
    origins = {tuple(d.table["origin_m"]) for d in draws.values()}
    assert len(origins) == len(draws), "two seeds drew the same board"


def test_the_angles_name_the_rotation_the_presets_are_its_corners():
    wall = np.array([[0, 0, -1], [-1, 0, 0], [0, 1, 0]], float)  # sim/board.py's wall preset
    table = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]], float)
    assert np.allclose(rotation_from_angles(90.0, 0.0, 0.0), wall, atol=1e-12)
    assert np.allclose(rotation_from_angles(0.0, 0.0, 0.0), table, atol=1e-12)
    R = rotation_from_angles(37.0, 20.0, -30.0)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    # tilt is the normal's angle from vertical; the roll leaves the normal where it is
    assert np.degrees(np.arccos(R[2, 2])) == pytest.approx(37.0)
    assert np.allclose(rotation_from_angles(37.0, 20.0, 10.0)[:, 2], R[:, 2])


def test_every_drawn_board_is_within_the_stated_ranges_and_faces_the_robot(draws):
    for s, d in draws.items():
        assert 0.0 <= d.tilt_deg <= 90.0 and abs(d.turn_deg) <= 45.0 and abs(d.roll_deg) <= 45.0, s
        R = matrix_from_quat_wxyz(np.array(d.table["quat_wxyz"]))
        centre = np.array(d.table["origin_m"]) + R @ np.array([*d.table["size_m"], 0.0]) / 2
        assert centre[:2] @ R[:2, 2] <= 1e-9, f"seed {s}: the board looks away from the robot"
        assert np.degrees(np.arccos(np.clip(R[2, 2], -1, 1))) == pytest.approx(d.tilt_deg, abs=1e-4)


@pytest.mark.slow
def test_the_simulator_starts_on_every_drawn_board_with_the_most_stains(draws):
    for s, d in draws.items():
        sim = SimCore(SimParams.from_table({"board": d.table, "seed": s, "dirt": {"stains": MAX_STAINS},
                                            "camera": {"enabled": True}}))
        try:
            assert len(sim.dirt.stains) == MAX_STAINS
        finally:
            sim.close()


def test_a_refused_draw_says_why_and_an_unreachable_board_is_refused():
    far = {"preset": "custom", "origin_m": [1.6, 0.3, 0.3], "quat_wxyz": [0.5, 0.5, -0.5, -0.5], "size_m": [0.6, 0.5]}
    why = board_refusal(far, RobotModel())
    assert why is not None and "beyond the stretched arm" in why
    low = {"preset": "custom", "origin_m": [0.4, 0.3, -0.2], "quat_wxyz": [0.5, 0.5, -0.5, -0.5],
           "size_m": [0.6, 0.5]}
    assert "mounting plane" in board_refusal(low, RobotModel())
    assert all(isinstance(r, str) and r for d in (sample_board(s) for s in (0, 1)) for r in d.refused)


#: A board the simulator starts on whose stain region's near edge the elbow cannot reach: it folds past its limit
#: there. Seed 69's first draw that passes the simulator's checks alone (sim/board.py check_board: the region's
#: centre and corners); the controller skips two of its four stains (the cell ends incomplete).
NEAR_SHOULDER = {"preset": "custom", "origin_m": [0.454434, 0.202834, 0.098618],
                 "quat_wxyz": [0.545401999, 0.026884984, -0.326512865, -0.771494138], "size_m": [0.8985, 0.5271]}


def _controller_reach_problems(table: dict, seed: int, stains: int) -> list[str]:
    """The reasons the controller's reach test (controller/free_motion.py stain_reach_problem, the executor's) gives
    for the stains the simulator places on ``table`` from ``seed``, each taken whole (its size along its axis and
    its size / aspect across)."""
    from arm.reach import arm_reach
    from controller.executor_types import BoardPose
    from controller.free_motion import FreeMotion
    from controller.params import ExecutorParams, ForceParams
    from lampskit.core.planner_types import Stain

    params = SimParams.from_table({"board": table, "seed": seed, "dirt": {"stains": stains}})
    board = board_from_params(params.board)
    motion = FreeMotion(ExecutorParams(), ForceParams())
    motion.arm = arm_reach(RobotModel())
    pose = BoardPose(board.R.copy(), board.origin_m.copy(), board.size_m.copy())
    out = []
    for s in make_stains(params, board):
        why = motion.stain_reach_problem(pose, Stain(s.id, np.array(s.centre_m), s.size_m, s.size_m / s.aspect,
                                                     s.angle_rad))
        if why is not None:
            out.append(f"stain {s.id}: {why}")
    return out


def test_a_board_whose_stain_region_the_elbow_cannot_reach_is_refused_as_the_controller_would_skip_its_stains():
    SimCore(SimParams.from_table({"board": NEAR_SHOULDER, "seed": 69, "dirt": {"stains": 4}})).close()  # it starts
    skipped = _controller_reach_problems(NEAR_SHOULDER, 69, 4)
    assert len(skipped) == 2 and all("elbow would fold past its limit" in why for why in skipped), skipped
    why = board_refusal(NEAR_SHOULDER, RobotModel(), 69)
    assert why is not None and why.startswith("the stain region's point") and "elbow would fold" in why, why
    assert NEAR_SHOULDER not in [d.table for d in (sample_board(s) for s in (69,))]


def test_the_controller_skips_no_stain_the_simulator_places_on_a_drawn_board(draws):
    for s, d in draws.items():
        assert _controller_reach_problems(d.table, s, MAX_STAINS) == [], f"seed {s}"
        for n in (1, 3):
            assert _controller_reach_problems(d.table, s, n) == [], f"seed {s}, {n} stains"


def test_random_boards_by_name_for_lamps_up_and_the_campaign():
    env = board_env("random:5")
    table = {k.removeprefix("LAMPS__SIM__BOARD__").lower(): json.loads(v) for k, v in env.items()}
    assert table == random_board_table("random:5") == sample_board(5).table
    for bad in ("random:", "random:-1", "random:x"):
        with pytest.raises(UpError, match="random"):
            board_env(bad)
    assert random_seed_of("wall") is None
    with pytest.raises(ConfigError):
        sample_board(-1)
    cells = cells_of([4, 7], [2], ["random", "wall"])
    assert [c.board for c in cells] == ["random:4", "wall"]  # seed s takes boards[s mod 2]
    cells = cells_of([4, 7], [2], ["random"])
    assert [c.board for c in cells] == ["random:4", "random:7"] and cells[0].name == "random-s4-n2"


def test_random_boards_written_as_files_are_the_same_boards_with_the_same_stains(tmp_path):
    """bench/random_board_files.py: a campaign at another commit given ``bNNN.toml`` runs seed s's random board
    (the file's table is ``random:s``'s) and the same stains (the campaign's model of the sim's stains)."""
    import subprocess
    import sys

    from launch.campaign import _board_table, cell_stains
    from launch.campaign_cells import Cell

    from .conftest import REPO

    r = subprocess.run([sys.executable, str(REPO / "bench" / "random_board_files.py"), "--seeds", "3,8",
                        "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b003.toml", "b008.toml"]
    for s in (3, 8):
        path = str(tmp_path / f"b{s:03d}.toml")
        assert _board_table(path) == random_board_table(f"random:{s}")
        (areas, centres), (areas_f, centres_f) = (cell_stains(Cell(s, 6, b), _board_table(b))
                                                  for b in (f"random:{s}", path))
        np.testing.assert_array_equal(areas, areas_f)
        np.testing.assert_array_equal(centres, centres_f)
    bad = subprocess.run([sys.executable, str(REPO / "bench" / "random_board_files.py"), "--seeds", "x",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--seeds" in bad.stderr, bad.stderr
