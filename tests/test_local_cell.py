"""The network-free cell: the in-process bus behind ServiceNode, ``lamps up --no-network``'s refusals, and a
campaign's workers that run such cells one after another (a kept renderer, a worker that dies under a cell, the
same report for a cell whatever ran before it in the worker).

Whole network-free cells run in tests/test_campaign.py (a campaign's cells, compared with the Zenoh cell and
across a Ray cluster) and tests/test_launch.py (the adaptive streak).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgspec
import numpy as np
import pytest

from interfaces.codec import encode
from interfaces.messages import SCHEMA_VERSION, Capabilities, Estop, RobotState, TorqueCommand
from runtime.config import ZenohSettings
from runtime.local_bus import LocalBus, LocalNode

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _state(seq: int) -> RobotState:
    return RobotState(seq=seq, stamp_ns=1, q_rad=[0.0] * 7, dq_rad_s=[0.0] * 7, tau_nm=[0.0] * 7,
                      wrench_world=[0.0] * 6, capabilities=Capabilities(False, [100.0] * 7, "test"))


def test_a_put_reaches_every_matching_reader_at_once_in_order_decoded_and_checked():
    bus = LocalBus()
    settings = ZenohSettings(robot_id="cell-a")
    with LocalNode("sim", bus, settings) as sim, LocalNode("controller", bus, settings) as ctrl, \
            LocalNode("other", bus, ZenohSettings(robot_id="cell-b")) as other:
        inbox = ctrl.inbox(ctrl.keys.robot_state, RobotState, maxlen=8)
        newest = ctrl.latest(ctrl.keys.robot_state, RobotState, depth=3)
        elsewhere = other.inbox(other.keys.robot_state, RobotState)
        everything = []
        sub = bus.subscribe(f"{settings.keys.prefix}/**", everything.append)
        for k in range(5):
            sim.publish(sim.keys.robot_state, _state(k))
        assert [inbox.get(0.0).seq for _ in range(5)] == [0, 1, 2, 3, 4] and inbox.get(0.0) is None
        assert [m.seq for m in newest.take_all()] == [2, 3, 4]  # the newest `depth` samples, oldest first
        assert elsewhere.get(0.0) is None  # another cell's prefix hears nothing
        assert [str(s.key_expr) for s in everything] == [settings.keys.robot_state] * 5
        sub.undeclare()
        # a published message reaches its readers as itself (frozen messages): one object for every reader
        twice = ctrl.inbox(ctrl.keys.robot_state, RobotState)
        published = _state(9)
        sim.publish(sim.keys.robot_state, published)
        assert twice.get(0.0) is newest.take() is inbox.get(0.0) is published
        # bytes put on the bus are decoded once for the readers of a type
        bus.put(settings.keys.robot_state, encode(_state(10)))
        got = twice.get(0.0)
        assert got == _state(10) and got is not _state(10) and newest.take() is got is inbox.get(0.0)
        # bytes that are not the key's message are counted and dropped by the same readers as on Zenoh
        bus.put(settings.keys.robot_state, b"\x93not a state")
        assert inbox.get(0.0) is None and sum(inbox.bad.values()) == 1 and inbox.received == 8
        assert sum(twice.bad.values()) == 1  # each reader counts a bad payload, as each process would
        assert len(everything) == 5
        # a TorqueCommand on the state key is refused as on the wire
        sim.publish(sim.keys.robot_state, TorqueCommand(seq=1, stamp_ns=1, tau_nm=[0.0] * 7))
        assert inbox.get(0.0) is None and sum(inbox.bad.values()) == 2 and sum(twice.bad.values()) == 2
        # and a state of another schema version, as the codec refuses it
        sim.publish(sim.keys.robot_state, msgspec.structs.replace(_state(11), version=SCHEMA_VERSION + 1))
        assert inbox.get(0.0) is None and sum(inbox.bad.values()) == 3 and sum(twice.bad.values()) == 3
        # liveliness: every node's token, under its cell's prefix
        assert ctrl.alive_services() == {"sim", "controller"} and other.alive_services() == {"other"}
    assert bus.tokens(f"{settings.keys.prefix}/**") == []  # closed nodes take their tokens with them


def test_each_node_has_its_own_session_id_and_an_estop_reaches_both_sides():
    bus = LocalBus()
    with LocalNode("a", bus) as a, LocalNode("b", bus) as b:
        assert str(a.session.zid()) != str(b.session.zid())
        ins = [n.inbox(n.keys.controller_estop, Estop) for n in (a, b)]
        a.publish(a.keys.controller_estop, Estop(stamp_ns=1, engaged=True, reason="test", source="a"))
        assert all(i.get(0.0).engaged for i in ins)


@pytest.mark.parametrize("args, match", [
    (["--mode", "realtime"], "--no-network runs one simulated cell in lock-step only"),
    (["--robot", "lbr-sim"], "--no-network runs one simulated cell in lock-step only"),
    (["--foxglove", "8999"], "--no-network runs one simulated cell in lock-step only"),
    (["--cells", "2"], "--no-network runs one simulated cell in lock-step only"),
])
def test_what_needs_the_network_is_refused_before_anything_starts(tmp_path, args, match):
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "up", "--no-network", "--out", str(tmp_path / "r"),
                        *args], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert r.returncode == 1 and match in r.stderr, r.stderr
    assert not (tmp_path / "r").exists()


def test_session_ids_count_per_bus_so_a_cell_gets_the_same_ones_whatever_ran_before():
    first, second = LocalBus(), LocalBus()
    ids = [[str(LocalNode(n, bus).__enter__().session.zid()) for n in ("sim", "controller")] for bus in (first, second)]
    assert ids[0] == ids[1] == [f"{1:032x}", f"{2:032x}"]


def test_a_kept_renderer_draws_the_frame_a_new_one_draws_with_its_counters_from_zero():
    from sim.core import SimCore
    from sim.params import SimParams
    from sim.renderer import KEPT, keep_renderers, open_camera, release_camera

    p = SimParams.from_table({"seed": 3, "dirt": {"stains": 2}, "board": {"preset": "wall"}})
    core = SimCore(p)
    q_other = core.q_start + 0.2

    def frame(camera, q):
        camera.request(1, 0, 0, q, core.dirt.dirt, 0)
        return camera.take(30.0).data

    keep_renderers()
    try:
        camera = open_camera(p, core.board, core.q_start, core.dirt.dirt.shape)
        fresh = frame(camera, core.q_start)
        frame(camera, q_other)  # an arm elsewhere, then the frame asked for last left untaken
        camera.request(2, 0, 0, q_other, np.zeros_like(core.dirt.dirt), 0)
        release_camera(camera)
        kept = open_camera(SimParams.from_table({"seed": 4, "dirt": {"stains": 1}, "board": {"preset": "wall"}}),
                           core.board, core.q_start, core.dirt.dirt.shape)  # another seed: the same scene
        assert kept is camera and (kept.requested, kept.rendered, kept.skipped) == (0, 0, 0)
        assert frame(kept, core.q_start) == fresh and kept.rendered == 1
        release_camera(kept)
    finally:
        keep_renderers(False)
        core.close()
    assert not KEPT and kept.dead  # closed once nobody keeps renderers


def test_a_worker_that_dies_under_a_cell_makes_a_cell_without_a_report_and_the_next_cell_a_new_worker(
        tmp_path, learned_skill_file):
    from launch.campaign_cells import Cell
    from launch.campaign_pool import WorkerPool

    with WorkerPool() as pool:
        result = {}
        run = threading.Thread(target=lambda: result.update(
            first=pool.run_cell(0, Cell(0, 1, "wall"), learned_skill_file, tmp_path, 60.0)))
        run.start()
        deadline = time.monotonic() + 120
        while not (tmp_path / "cells" / "wall-s0-n1" / "run.json").parent.is_dir():  # the cell under way
            assert time.monotonic() < deadline and run.is_alive()
            time.sleep(0.05)
        worker = pool._all[0]
        worker._proc.kill()
        run.join(60)
        report, run_dir, why = result["first"]
        assert report is None and run_dir == str(tmp_path / "cells" / "wall-s0-n1")
        assert why.startswith("the campaign worker died under the cell (exit -9)"), why
        # the next cell: a new worker, whose lamps up refuses a missing skill file as the command does
        report, _, why = pool.run_cell(1, Cell(1, 1, "wall"), tmp_path / "no-skill.json", tmp_path, 60.0)
        assert report is None and "no-skill.json: no such file" in why, why
        assert len(pool._all) == 2 and not worker.alive and pool._all[1].alive


#: Report fields that follow the wall clock in a network-free cell (the controller publishes its status, which the
#: launcher watches for the DONE it holds, at a wall-clock rate): left out when two runs of a cell are compared.
WALL_CLOCK_FIELDS = ("duration_s", "loop_timing", "counters", "sim_time_s", "trace_ticks", "run_dir")


def _results(report: dict) -> dict:
    out = {k: v for k, v in report.items() if k not in WALL_CLOCK_FIELDS}
    out["phase_time_s"] = {k: v for k, v in report["phase_time_s"].items() if k not in ("DONE", "all")}
    out["motion_peaks"] = {p: {k: v for k, v in m.items() if k != "ticks"} for p, m in report["motion_peaks"].items()
                           if p != "DONE"}
    return out


@pytest.mark.slow
def test_a_cell_gives_the_same_report_first_or_second_in_a_worker(tmp_path, learned_skill_file):
    """The same seeded cell twice in one worker (the second with the first's renderer, imports and frozen heap):
    the same report, but for what follows the wall clock."""
    from launch.campaign_cells import Cell
    from launch.campaign_pool import WorkerPool

    cell = Cell(0, 1, "wall")
    with WorkerPool() as pool:
        first, _, why = pool.run_cell(0, cell, learned_skill_file, tmp_path / "a", 300.0)
        assert first is not None, why
        second, _, why = pool.run_cell(1, cell, learned_skill_file, tmp_path / "b", 300.0)
        assert second is not None, why
        assert len(pool._all) == 1
    assert first["outcome"] == "cleaned" and not first["faults"]
    assert _results(second) == _results(first)
    run = json.loads((Path(tmp_path / "b" / "cells" / cell.name / "run.json")).read_text())
    assert run["network"] == "none"
    # the stop on the recording's clock, which runs faster than the wall here: a wall time read against it took a
    # DONE cell's phase from mid-wipe (outcome "incomplete")
    from launch.record import RECORDING, read_recording

    status = read_recording(tmp_path / "b" / "cells" / cell.name / RECORDING)[run["key_prefix"] + "/controller/status"]
    assert status[0][0] <= run["stopping_wall_ns"] <= status[-1][0] + 10**9, (run["stopping_wall_ns"], status[-1][0])
    assert status[-1][1]["phase"] == "DONE"
