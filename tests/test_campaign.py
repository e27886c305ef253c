"""``lamps campaign``: seeded cells run whole, several at once, summed up against a lower bound on the robot time."""

from __future__ import annotations

import contextlib
import json
import math
import os
import secrets
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from launch.campaign import cell_stains, felt_model
from launch.campaign_bounds import cell_bound_s, felt_path_m, lower_bound_s, mst_length_m
from launch.campaign_cells import CampaignError, Cell, cells_of, parse_range
from launch.campaign_table import markdown, row_of, summarize

from .zenoh_helpers import free_port

REPO = Path(__file__).resolve().parent.parent
TILTED = REPO / "config" / "boards" / "tilted.toml"


@pytest.mark.parametrize("text, want", [("0-3", [0, 1, 2, 3]), ("5", [5]), ("1,4,7-9", [1, 4, 7, 8, 9]),
                                        ("3-3,2", [2, 3])])
def test_ranges(text, want):
    assert parse_range(text, "seeds") == want


@pytest.mark.parametrize("text", ["5-2", "a", "1-b", "-1", ""])
def test_bad_ranges_are_refused_naming_the_part(text):
    with pytest.raises(CampaignError, match="--seeds"):
        parse_range(text, "seeds")


def test_each_seed_cycles_through_stain_counts_and_boards_the_same_whatever_else_runs():
    cells = cells_of([0, 1, 2, 3, 7], [1, 2, 3], ["wall", "table"])
    assert cells[:4] == [Cell(0, 1, "wall"), Cell(1, 2, "table"), Cell(2, 3, "wall"), Cell(3, 1, "table")]
    assert cells[4] == Cell(7, 2, "table") == cells_of([7], [1, 2, 3], ["wall", "table"])[0]
    with pytest.raises(CampaignError):
        cells_of([], [1], ["wall"])


def test_the_lower_bound_is_the_swept_area_plus_the_shortest_network_at_the_speed_limit():
    centres = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.4], [0.0, 0.4]])
    assert mst_length_m(centres) == pytest.approx(0.3 + 0.3 + 0.4)  # a rectangle: three sides
    assert mst_length_m(centres[:1]) == 0.0
    bound = lower_bound_s([0.01, 0.02], centres[:2], 0.1, 0.5)
    assert bound == pytest.approx(0.03 / (0.1 * 0.5) + 0.3 / 0.5)
    with pytest.raises(CampaignError):
        lower_bound_s([0.01], centres[:1], 0.0, 0.5)


def test_cell_stains_are_the_ones_the_sim_makes_for_that_seed_and_board():
    from sim.board import board_from_params
    from sim.core import make_stains
    from sim.params import SimParams

    areas, centres = cell_stains(Cell(4, 3, "table"), {"preset": "table"})
    params = SimParams.from_table({"seed": 4, "dirt": {"stains": 3}, "board": {"preset": "table"}})
    truth = make_stains(params, board_from_params(params.board))
    np.testing.assert_allclose(centres, [s.centre_m for s in truth])
    assert areas == pytest.approx([math.pi / 4 * s.size_m ** 2 / s.aspect for s in truth])


def test_a_random_board_is_sampled_when_its_row_is_made_once_and_a_bad_board_file_is_refused_first(monkeypatch,
                                                                                                    tmp_path):
    """The campaign samples a random board when it makes that cell's row, not all of them before the first cell
    runs, and once whatever asks; a board file it cannot read is refused before any cell runs."""
    import launch.campaign as campaign

    sampled: list[str] = []
    real = campaign._board_table
    monkeypatch.setattr(campaign, "_board_table", lambda b: sampled.append(b) or real(b))
    cells = cells_of(list(range(1000)), [1, 2], ["random", "table"])
    bounds = campaign._Bounds(cells)
    assert sampled == ["table"]  # a preset is read at once, no random board sampled
    assert cells[2].board == "random:2"
    first = bounds.of(cells[2])
    assert bounds.of(cells[2]) is first and sampled == ["table", "random:2"]
    np.testing.assert_allclose(first[0][1], cell_stains(cells[2], real("random:2"))[1])
    assert first[1] > 0
    bad = tmp_path / "bad.toml"
    bad.write_text("this is [not toml\n")
    with pytest.raises(CampaignError, match="bad.toml"):
        campaign._Bounds([Cell(0, 1, str(bad))])


def test_a_resume_keeps_the_table_row_of_a_cell_whose_folder_holds_its_report_sampling_no_board(monkeypatch, tmp_path):
    """Resuming a campaign whose cell folders are still on the machine takes each finished cell's row from the
    table as it is (a random board is sampled 0.3-3 s: 1,000 kept rows were minutes of one core before the first
    cell); a row whose run folder is another one is made again from the folder's report."""
    import launch.campaign as campaign

    out = tmp_path / "campaign"
    cells = [Cell(5, 2, "random:5"), Cell(6, 1, "wall")]
    bounds = campaign._Bounds(cells)
    rows = []
    for c, removed in zip(cells, (0.991, 0.985)):
        run_dir = out / "cells" / c.name
        run_dir.mkdir(parents=True)
        (run_dir / "report.json").write_text(json.dumps(_report(removed, 20.0)))
        (run_dir / "run.json").write_text(json.dumps({"outcome": "cleaned"}))
        rows.append(bounds.row(c, _report(removed, 20.0), str(run_dir), ""))
    rows[1]["run_dir"] = "elsewhere/wall-s6-n1"  # not this folder's row: made again from the report
    (out / "campaign.json").write_text(json.dumps({"cells": rows}))
    sampled: list[str] = []
    real = campaign._board_table
    monkeypatch.setattr(campaign, "_board_table", lambda b: sampled.append(b) or real(b))
    said: list[str] = []
    result = campaign.run_campaign(cells, out, 1, tmp_path / "skill.json", 60.0, "lamps campaign", echo=said.append,
                                   resume=True, network=False)
    assert sampled == ["wall"]  # the preset read up front; random:5 not sampled again
    assert said == ["resuming: 2 of 2 cells already have a report (0 of them only in the table), 0 to run"]
    assert json.dumps(result["cells"][0]) == json.dumps(rows[0])  # the very row (NaN where the report has no figure)
    assert result["cells"][1]["run_dir"] == str(out / "cells" / "wall-s6-n1")
    assert result["cells"][1]["dirt_removed"] == pytest.approx(0.985)


def _report(removed: float, robot_s: float, faults=()):
    return {"outcome": "cleaned" if removed >= 0.95 else "incomplete", "dirt_removed_fraction": removed,
            "sim_time_s": robot_s, "max_contact_force_n": 12.0, "motion_peaks": {"all": {"jerk_m_s3": 300.0,
                                                                                         "speed_m_s": 0.4}},
            "faults": [{"phase": p, "reason": r} for p, r in faults]}


def test_the_felt_needs_its_sliding_under_every_point_and_the_cell_bound_adds_the_fixed_moves():
    felt = {"pad_area_m2": 0.006, "rate_per_n_m": 2.0, "force_over_threshold_n": 8.0, "level": 0.03}
    slide = math.log(1 / 0.03) / 16.0  # 0.219 m under every point
    assert felt_path_m(0.001, **felt) == pytest.approx(slide)  # smaller than the pad: one slide's length
    assert felt_path_m(0.012, **felt) == pytest.approx(2 * slide)  # twice the pad's area: twice the path
    centres = np.array([[0.0, 0.0], [0.3, 0.0]])
    assert cell_bound_s(9.0, [0.001, 0.012], centres, felt, 0.5) == pytest.approx(9.0 + (3 * slide + 0.3) / 0.5)
    with pytest.raises(CampaignError):
        felt_path_m(0.01, 0.0, 2.0, 8.0, 0.03)


def test_a_row_takes_the_fixed_moves_from_the_skill_start_and_the_retreat():
    report = {**_report(1.0, 20.0), "skill_start_s": 7.0, "phase_time_s": {"RETREAT": 3.0, "WIPE": 8.0}}
    felt = felt_model()
    stains = ([0.002], np.array([[0.2, 0.2]]))
    row = row_of(Cell(0, 1, "wall"), report, 0.5, "a", stains=stains, felt=felt, speed_m_s=0.5)
    assert row["fixed_moves_s"] == 10.0 and row["time_per_stain_s"] == 10.0
    assert row["cell_bound_s"] == pytest.approx(cell_bound_s(10.0, *stains, felt, 0.5))
    assert row["time_over_cell_bound"] == pytest.approx(20.0 / row["cell_bound_s"])
    old = row_of(Cell(0, 1, "wall"), _report(1.0, 20.0), 0.5, "a", stains=stains, felt=felt)
    assert math.isnan(old["cell_bound_s"])  # a report from before the skill start was reported: no bound
    # the robot time ends at the DONE the run ended in; the cell's time (with the launcher's look) is kept beside
    done = row_of(Cell(0, 1, "wall"), {**report, "job_end_s": 17.5}, 0.5, "a", stains=stains, felt=felt)
    assert done["robot_time_s"] == 17.5 and done["cell_time_s"] == 20.0 and done["time_per_stain_s"] == 7.5
    assert done["time_over_cell_bound"] == pytest.approx(17.5 / done["cell_bound_s"])
    assert done["cell_time_over_cell_bound"] == pytest.approx(20.0 / done["cell_bound_s"])
    assert row["robot_time_s"] == 20.0  # not DONE at the end (or an older report): the whole cell
    # a run that re-passed a stain: its first retreat and look are no fixed move, only the final retreat is
    repass = row_of(Cell(0, 1, "wall"), {**report, "final_retreat_s": 2.0}, 0.5, "a", stains=stains, felt=felt)
    assert repass["fixed_moves_s"] == 9.0


def test_phase_times_and_the_skill_start_come_from_the_trace():
    from controller.core import PHASE_CODES
    from launch.report_maths import job_end, phase_times, skill_start

    col = {"t_s": 0, "phase": 1}
    codes = [PHASE_CODES["APPROACH"]] * 3 + [PHASE_CODES["TRANSITION"]] * 2 + [PHASE_CODES["WIPE"]] * 3
    t = [2.0, 2.001, 2.002, 2.003, 2.004, 2.5, 2.501, 2.502]  # a gap of half a second (nobody's)
    tr = np.column_stack([t, codes])
    times = phase_times(tr, col)
    assert times["APPROACH"] == pytest.approx(0.003) and times["TRANSITION"] == pytest.approx(0.001)
    assert times["WIPE"] == pytest.approx(0.002) and times["all"] == pytest.approx(0.006)
    assert skill_start(tr, col) == 2.003 and skill_start(tr[:3], col) is None
    # the job ends at the first tick of the DONE the recording ends in (not an earlier DONE left again)
    done, wipe = PHASE_CODES["DONE"], PHASE_CODES["WIPE"]
    tr2 = np.column_stack([[1.0, 1.001, 1.002, 1.003, 1.004, 1.005], [wipe, done, wipe, done, done, done]])
    assert job_end(tr2, col) == 1.003 and job_end(tr2[:3], col) is None and job_end(tr2[:0], col) is None
    assert job_end(tr2[3:], col) == 1.003
    # the final retreat: only the RETREAT that leads into that DONE (a look and a re-pass before it are not it)
    from launch.report_maths import final_retreat

    retreat = PHASE_CODES["RETREAT"]
    phases = [wipe, retreat, retreat, done, wipe, wipe, retreat, retreat, retreat, done, done]
    tr3 = np.column_stack([1.0 + 0.001 * np.arange(len(phases)), phases])
    assert final_retreat(tr3, col) == pytest.approx(0.003)
    assert final_retreat(tr3[:9], col) is None and final_retreat(tr2, col) is None  # not DONE / no RETREAT


def test_rows_and_summary_count_success_faults_and_cells_without_a_report():
    rows = [row_of(Cell(0, 1, "wall"), _report(1.0, 20.0), 10.0, "a"),
            row_of(Cell(1, 2, "wall"), _report(0.97, 30.0), 10.0, "b"),  # below 98 %: ran, not a success
            row_of(Cell(2, 1, "table"), _report(1.0, 25.0, [("ROBOT", "braked"), ("FAULT", "force cap")]), 5.0, "c"),
            row_of(Cell(3, 1, "table"), _report(1.0, 40.0, [("ROBOT", "braked")]), 8.0, "d"),
            row_of(Cell(4, 1, "wall"), None, 7.0, "e", why="lamps up: error: port busy"),
            row_of(Cell(5, 2, "wall"), {**_report(0.6, 30.0), "final_reason": "1 stain(s) left: stain 1 out of the "
                   "arm's reach (x)", "counters": {"controller": {"stains_out_of_reach": 1}}}, 7.0, "f")]
    assert [r["success"] for r in rows] == [True, False, False, True, False, False]
    assert rows[5]["stains_out_of_reach"] == 1 and rows[0]["stains_out_of_reach"] == 0
    assert rows[2]["faults"] == 1 and rows[2]["robot_events"] == 1 and rows[2]["fault_reasons"] == ["force cap"]
    s = summarize(rows)
    assert s["all fixed"]["runs"] == 6 and s["all fixed"]["success_rate"] == pytest.approx(2 / 6)
    assert s["all fixed"]["no_report"] == 1
    assert s["all fixed"]["robot_acted_cells"] == 2 and s["all fixed"]["out_of_reach_cells"] == 1
    assert s["all fixed"]["force_over_bound_cells"] == 0 and s["all fixed"]["joint_over_bound_cells"] == 0
    hot = row_of(Cell(6, 1, "wall"), {**_report(1.0, 20.0), "max_contact_force_n": 20.5,
                                     "max_joint_speed_ratio": 0.81}, 7.0, "g")
    hs = summarize(rows + [hot])["all fixed"]
    assert hs["force_over_bound_cells"] == 1 and hs["joint_over_bound_cells"] == 1
    assert "| 20.5 (1) |" in markdown(summarize(rows + [hot]), rows + [hot], "cmd")
    table = markdown(s, rows, "lamps campaign ...")
    assert "| wall-s5-n2 | incomplete | 60.0% |" in table and "stain 1 out of the arm's reach (x) |" in table
    assert s["wall fixed"]["dirt_removed_min"] == pytest.approx(0.6)
    assert s["wall fixed"]["time_over_bound_median"] == 3.0
    assert s["table fixed"]["faults"] == 1 and s["table fixed"]["time_over_bound_max"] == pytest.approx(5.0)
    both = summarize(rows + [row_of(Cell(0, 1, "wall", "adaptive"), _report(1.0, 15.0), 10.0, "f")])
    assert both["all adaptive"]["runs"] == 1 and both["wall adaptive"]["robot_time_median_s"] == 15.0
    assert both["all fixed"]["runs"] == 6


def test_each_seed_runs_once_per_wiping_mode_under_its_own_name():
    cells = cells_of([0, 1], [1, 2], ["wall"], ("fixed", "adaptive"))
    assert [c.name for c in cells] == ["wall-s0-n1", "wall-s0-n1-adaptive", "wall-s1-n2", "wall-s1-n2-adaptive"]
    with pytest.raises(CampaignError, match="'sloppy' is not one of"):
        cells_of([0], [1], ["wall"], ("sloppy",))


def test_each_seed_runs_once_per_plant_and_the_plant_reaches_the_simulator_only():
    """A plant is the simulator's [sim.plant] table, through the cell's environment, the same for a seed in any
    campaign; the controller's parameters never see it."""
    import json

    from controller.params import ControllerParams
    from launch.campaign_plants import PLANTS, plant_error, plant_table
    from launch.campaign_run import cell_env
    from runtime.config import load_config
    from sim.params import SimParams

    cells = cells_of([3], [2], ["wall"], ("fixed",), plants=PLANTS)
    assert [c.name for c in cells] == ["wall-s3-n2", "wall-s3-n2-stuerz2017", "wall-s3-n2-random", "wall-s3-n2-tool",
                                       "wall-s3-n2-arm"]
    with pytest.raises(CampaignError, match="--plants: 'heavy' is not one of"):
        cells_of([0], [1], ["wall"], plants=("heavy",))
    for cell in cells:
        env = cell_env(cell)
        table = {k.removeprefix("LAMPS__SIM__PLANT__").lower(): json.loads(v) for k, v in env.items()
                 if k.startswith("LAMPS__SIM__PLANT__")}
        assert table == plant_table(cell.plant, 3) and not any(k.startswith("LAMPS__CONTROLLER__PLANT")
                                                               for k in env)
        old = dict(os.environ)
        try:
            os.environ.update(env)
            cfg = load_config(None)
            sim = SimParams.from_table(cfg.table("sim"))
            assert ControllerParams.from_table(cfg.table("controller")) == ControllerParams.from_table({}), cell.name
        finally:
            os.environ.clear()
            os.environ.update(old)
        assert sim.plant.body_is_described == (cell.plant == "nominal"), cell.name
    tool = plant_table("tool", 3)
    assert 0.2 <= tool["tool_mass_kg"] <= 1.5 and plant_table("tool", 3) == tool != plant_table("tool", 4)
    assert plant_error("nominal", 0) == 0.0 < plant_error("tool", 3) and 0.0 < plant_error("random", 3) < 0.3
    assert plant_table("arm", 3) == {**plant_table("random", 3), **tool}
    assert plant_error("arm", 3) == pytest.approx(plant_error("random", 3) + plant_error("tool", 3))


def test_the_table_groups_plants_and_reports_tracking_force_spread_and_joint_speed():
    rows = [row_of(Cell(0, 1, "wall"), {**_report(1.0, 20.0), "tracking_rms_m": 0.002, "normal_force_std_n": 0.6,
                                       "max_joint_speed_ratio": 0.5}, 10.0, "a"),
            row_of(Cell(0, 1, "wall", plant="random"), {**_report(1.0, 21.0), "tracking_rms_m": 0.004,
                                                        "normal_force_std_n": 1.2, "max_joint_speed_ratio": 0.7},
                   10.0, "b")]
    s = summarize(rows)
    assert set(s) == {"wall fixed", "wall fixed random", "all fixed"}
    assert s["wall fixed random"]["tracking_rms_median_m"] == 0.004 and s["all fixed"]["force_std_max_n"] == 1.2
    assert s["all fixed"]["joint_speed_ratio_max"] == 0.7
    table = markdown(s, rows, "cmd")
    assert "| wall fixed random | 1 |" in table and "1.20 (1.20) | 4.00 (4.00) | 0.70 (0) |" in table, table


def _campaign(*args: str, timeout: float = 900.0, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "runtime.cli", "campaign", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=timeout,
                          env={**(env or os.environ), "MPLBACKEND": "Agg"})


@pytest.mark.parametrize("args, match", [(["--seeds", "3-1"], "--seeds '3-1'"), (["--stains", "0-2"], "at least one"),
                                         (["--boards", "wall,moon"], "'moon' is not one of"),
                                         (["--jobs", "0"], "--jobs must be >= 1")])
def test_bad_options_are_one_line_errors_before_anything_runs(tmp_path, args, match):
    r = _campaign(*args, "--out", str(tmp_path / "c"), timeout=60)
    assert r.returncode == 1 and match in r.stderr and r.stderr.startswith("lamps campaign: error:"), r.stderr
    assert not (tmp_path / "c").exists()


def _cells_own_faults(row: dict) -> list[str]:
    """The faults in a cell's report that the cell made: not a silence of a service's status or of the recorder
    (phases SERVICE, RECORDER), which the wall clock measures, the machine's load (a Ray-run cell beside three
    other processes on the 2 cores showed "sim: no status for 1.1 s"), not the lock-step cell."""
    report = json.loads((Path(row["run_dir"]) / "report.json").read_text())
    return [f["reason"] for f in report["faults"] if f["phase"] not in ("SERVICE", "RECORDER")]


@pytest.mark.slow
def test_a_small_campaign_grows_its_table_survives_a_kill_resumes_and_writes_the_table(tmp_path, learned_skill_file):
    """One seeded one-stain cell on the wall board, fixed then adaptive, each a whole network-free cell in
    lock-step; the campaign is stopped (SIGTERM to it alone, as ``kill`` or ``pkill`` sends) while the second runs: its
    worker stops that cell, whose report shows the stop (the table holds the first only), and ``--resume`` runs
    the second again; then --summarize tables the campaign again from its folder. The two cells again as a campaign on
    a Ray cluster of two workers give the very same results (a network-free cell is deterministic for its seed),
    each drawing its plots (``--cell-plots``); and the fixed cell as a Zenoh cell
    (``lamps up``) the same outcome and dirt removed within 0.5 points."""
    out = tmp_path / "campaign"
    args = ["--seeds", "0", "--stains", "1", "--boards", "wall", "--wiping", "fixed,adaptive", "--jobs", "1",
            "--skill", str(learned_skill_file), "--out", str(out), "--no-network"]
    proc = subprocess.Popen([sys.executable, "-m", "runtime.cli", "campaign", *args], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
                            env={**os.environ, "MPLBACKEND": "Agg"})
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)  # what it printed so far
    reader.start()
    try:
        deadline = time.monotonic() + 600
        # the first cell's progress line out (its table written just before) and the second cell's folder made
        while not any("[1/2 done" in line for line in lines) \
                or not (out / "cells" / "wall-s0-n1-adaptive").is_dir():
            assert proc.poll() is None and time.monotonic() < deadline, "".join(lines)[-2000:]
            time.sleep(0.2)
        time.sleep(2.0)  # the second cell under way
        os.kill(proc.pid, signal.SIGTERM)  # the campaign alone: its worker hears of it from the kernel
        proc.wait(60)
        stopped = out / "cells" / "wall-s0-n1-adaptive"
        while not (stopped / "report.json").is_file():  # the worker stops its cell as lamps up does: a report
            assert time.monotonic() < deadline, "the stopped cell wrote no report"
            time.sleep(0.2)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # anything left of the group
        proc.wait()
        reader.join(10.0)
    assert json.loads((stopped / "run.json").read_text())["outcome"] == "stopped"
    printed = "".join(lines)
    assert "[1/2 done, 0 failed" in printed and "s left] wall-s0-n1:" in printed, printed[-2000:]
    half = json.loads((out / "campaign.json").read_text())
    assert [c["name"] for c in half["cells"]] == ["wall-s0-n1"]  # what it finished, kept
    first = (out / "cells" / "wall-s0-n1" / "report.json").stat().st_mtime_ns
    again = _campaign(*args)
    assert again.returncode == 1 and "exists: a campaign folder is never overwritten" in again.stderr, again.stderr
    r = _campaign(*args, "--resume")
    assert "resuming: 1 of 2 cells already have a report (0 of them only in the table), 1 to run" in r.stdout, \
        r.stdout[-2000:]
    assert (out / "cells" / "wall-s0-n1" / "report.json").stat().st_mtime_ns == first  # not run again
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    result = json.loads((out / "campaign.json").read_text())
    assert [c["name"] for c in result["cells"]] == ["wall-s0-n1", "wall-s0-n1-adaptive"]
    for c in result["cells"]:
        assert c["success"] and c["dirt_removed"] >= 0.98 and c["faults"] == 0, c
        assert c["robot_time_s"] > c["cell_bound_s"] > c["fixed_moves_s"] > 0  # a bound, and one no run beats
        assert c["cell_bound_s"] > c["lower_bound_s"] > 0
        assert (Path(c["run_dir"]) / "report.json").is_file()
    report = json.loads((Path(result["cells"][1]["run_dir"]) / "report.json").read_text())
    assert report["counters"]["controller"].get("adaptations", 0) >= 1  # the adaptive cell adapted
    assert result["summary"]["all fixed"]["success_rate"] == result["summary"]["all adaptive"]["success_rate"] == 1.0
    md = (out / "campaign.md").read_text()
    assert "| all fixed | 1 | 100% |" in md and "| all adaptive | 1 | 100% |" in md and "wall-s0-n1-adaptive" in md
    assert (out / "campaign.png").stat().st_size > 10_000
    # a campaign's cell writes report.json without plots; lamps report draws them from its recording
    cell_dir = Path(result["cells"][0]["run_dir"])
    assert report["plots"] == [] and not list(cell_dir.glob("*.png"))
    drawn = subprocess.run([sys.executable, "-m", "runtime.cli", "report", str(cell_dir)], cwd=REPO,
                           capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"}, timeout=300)
    assert drawn.returncode == 0, drawn.stderr[-2000:]
    assert len(json.loads((cell_dir / "report.json").read_text())["plots"]) >= 3 and list(cell_dir.glob("*.png"))
    # the table carried to another machine without the cell folders: --resume keeps its rows and runs nothing
    carried = tmp_path / "carried"
    carried.mkdir()
    shutil.copy(out / "campaign.json", carried / "campaign.json")
    moved = _campaign(*args[:-3], "--out", str(carried), "--no-network", "--resume")
    assert moved.returncode == 0, moved.stdout[-2000:] + moved.stderr[-2000:]
    assert "2 of 2 cells already have a report (2 of them only in the table), 0 to run" in moved.stdout, moved.stdout
    assert json.loads((carried / "campaign.json").read_text())["cells"] == result["cells"]
    assert not (carried / "cells").exists() and not (carried / "learn").exists()
    table = json.loads((carried / "campaign.json").read_text())
    table["cells"][0]["stains"] = 2  # a row that is not the cell its name says
    (carried / "campaign.json").write_text(json.dumps(table))
    wrong = _campaign(*args[:-3], "--out", str(carried), "--no-network", "--resume")
    assert wrong.returncode == 1 and "the row wall-s0-n1 of" in wrong.stderr and "stains 2" in wrong.stderr, \
        wrong.stderr
    again = _campaign("--summarize", str(out), "--out", str(tmp_path / "joint"))
    assert again.returncode == 0, again.stderr
    joint = json.loads((tmp_path / "joint" / "campaign.json").read_text())
    assert joint["summary"] == result["summary"] and joint["from"] == [str(out)]
    twice = _campaign("--summarize", str(out), str(out), "--out", str(tmp_path / "twice"))
    assert twice.returncode == 1 and "share cells (wall-s0-n1)" in twice.stderr

    # both cells again as tasks on a Ray cluster started with `ray start --head` (two workers): the same results
    port = free_port()
    ray_bin = str(Path(sys.executable).parent / "ray")
    # token authentication on, the token given to the cluster and the campaign (Ray's RAY_AUTH_TOKEN)
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(16)}
    start = subprocess.run([ray_bin, "start", "--head", "--num-cpus", "2", "--port", str(port), "--node-ip-address",
                            "127.0.0.1", "--include-dashboard", "false", "--disable-usage-stats"],
                           capture_output=True, text=True, env=env, timeout=180)
    assert start.returncode == 0, start.stderr[-2000:]
    try:
        on_ray = _campaign("--seeds", "0", "--stains", "1", "--boards", "wall", "--wiping", "fixed,adaptive",
                           "--jobs", "2", "--skill", str(learned_skill_file), "--out", str(tmp_path / "on-ray"),
                           "--ray", f"127.0.0.1:{port}", "--no-network", "--cell-plots", env=env)
    finally:
        subprocess.run([ray_bin, "stop", "--force"], capture_output=True, env=env, timeout=120)
    assert on_ray.returncode == 0, on_ray.stdout[-2000:] + on_ray.stderr[-2000:]
    ray_cells = json.loads((tmp_path / "on-ray" / "campaign.json").read_text())["cells"]
    assert sorted(c["name"] for c in ray_cells) == ["wall-s0-n1", "wall-s0-n1-adaptive"]
    local = {c["name"]: c for c in result["cells"]}
    same = ("outcome", "dirt_removed", "robot_time_s", "peak_contact_force_n")
    for c in ray_cells:
        want = local[c["name"]]
        assert {k: c[k] for k in same} == {k: want[k] for k in same}, (c, want)
        assert _cells_own_faults(c) == _cells_own_faults(want), (c, want)
        assert (Path(c["run_dir"]) / "report.json").is_file()
        assert list(Path(c["run_dir"]).glob("*.png"))  # --cell-plots reaches the cell on a Ray worker

    # the same cell over Zenoh (lamps up in lock-step: perception's frames land in wall time, so the robot time
    # spreads, more on a loaded machine: 20 % longer at two test workers): the same outcome, the dirt removed
    # within 0.5 points
    zenoh = _campaign("--seeds", "0", "--stains", "1", "--boards", "wall", "--wiping", "fixed", "--jobs", "1",
                      "--skill", str(learned_skill_file), "--out", str(tmp_path / "zenoh"))
    assert zenoh.returncode == 0, zenoh.stdout[-2000:] + zenoh.stderr[-2000:]
    result_z = json.loads((tmp_path / "zenoh" / "campaign.json").read_text())
    assert result_z["network"] is True and result["network"] is False
    assert not list(Path(result_z["cells"][0]["run_dir"]).glob("*.png"))  # the recorder's report drew none
    (c,), want = result_z["cells"], local["wall-s0-n1"]

    def cell_faults(row: dict) -> list[str]:  # a service's status late by a second or more (the report's SERVICE
        # line "no status for ...") is the loaded machine's, not the cell's: one in a CI run at two workers
        return [r for r in row["fault_reasons"] if "no status for" not in r]

    assert (c["outcome"], cell_faults(c)) == (want["outcome"], cell_faults(want)), (c["fault_reasons"], c, want)
    assert abs(c["dirt_removed"] - want["dirt_removed"]) < 0.005, (c, want)
    assert abs(c["robot_time_s"] - want["robot_time_s"]) < 0.4 * want["robot_time_s"], (c, want)


def test_a_pool_worker_runs_each_cell_in_its_own_environment_not_the_one_before(monkeypatch, tmp_path):
    """The network-free pool runs cells one after another in one process: a cell's plant variables must not
    stay for the next cell (a nominal cell after a tool cell ran with the tool)."""
    import launch.cli
    from launch import campaign_worker

    seen = []
    monkeypatch.setattr(launch.cli, "up_main", lambda argv: seen.append(
        {k: v for k, v in os.environ.items() if k.startswith("LAMPS__SIM__PLANT__")}) or 0)
    before = dict(os.environ)
    try:
        for plant in ("tool", "nominal", "random"):
            code, _, crashed = campaign_worker.run_here(Cell(5, 1, "wall", plant=plant), tmp_path / "s.json",
                                                        tmp_path / plant, 60.0)
            assert code == 0 and not crashed
    finally:  # run_here sets the process's environment, as a worker's: this test's process gets its own back
        os.environ.clear()
        os.environ.update(before)
    assert "LAMPS__SIM__PLANT__TOOL_MASS_KG" in seen[0] and seen[1] == {}, seen
    assert set(seen[2]) == {"LAMPS__SIM__PLANT__RANDOM_MASS_ERROR", "LAMPS__SIM__PLANT__RANDOM_COM_ERROR_M",
                            "LAMPS__SIM__PLANT__SEED"}, seen


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_a_pool_worker_ends_when_the_campaign_that_started_it_is_killed():
    """A campaign killed mid-run left its workers running their cells for minutes on cores nobody asked for."""
    parent = subprocess.Popen(
        [sys.executable, "-c", "import subprocess, time\nfrom launch.campaign_pool import Worker\nw = Worker()\n"
                               # a busy worker reads nothing: its stdin's end must not be what stops it (a sleeper
                               # keeps the pipe open as the cell in hand keeps the worker from reading)
                               "s = subprocess.Popen(['sleep', '60'], pass_fds=(w._stdin.fileno(),))\n"
                               "print(w._proc.pid, s.pid, flush=True)\ntime.sleep(120)"],
        cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        worker, sleeper = (int(x) for x in parent.stdout.readline().split())
        time.sleep(8.0)  # the worker is up: imports done, the request made
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(10.0)
        end = time.monotonic() + 30.0
        while time.monotonic() < end:
            try:
                os.kill(worker, 0)
                with open(f"/proc/{worker}/stat") as f:
                    if f.read().split()[2] == "Z":  # ended, not yet reaped by init
                        break
            except (ProcessLookupError, FileNotFoundError):
                break
            time.sleep(0.2)
        else:
            os.kill(worker, signal.SIGKILL)
            raise AssertionError("the worker outlived its campaign by 30 s")
    finally:
        parent.kill()
        with contextlib.suppress(ProcessLookupError, UnboundLocalError):
            os.kill(sleeper, signal.SIGKILL)
