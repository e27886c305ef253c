"""An operator's e-stop and its release over the whole cell: the arm lifts off and holds, then wipes on.

The compose cell's sim profile as local processes with access control
(:mod:`tests.cell_harness`), lock-step and real time. While the pad wipes,
the operator engages the e-stop on ``controller/estop`` and, after a hold of
1 s or 3 s, releases it on ``controller/estop/release``; the robot side and
the controller both hear both. Once both have released, the controller must
leave ESTOP and go on (re-approach, wipe, retreat): never stay latched
waiting for a release that has already happened.

The release reaches the two sides in either order (or the engage only one of
them); whichever order, ESTOP ends as soon as both have released. The
pad's lift-off, which stood still while the robot side held the arm, runs
after the release, PAUSED: under ``lamps up``, which ends a run held in
ESTOP for 5 s, a 3 s e-stop once ended the run as not cleaned because that
lift was still reported as ESTOP ("waiting for the robot side's e-stop
release").
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import pytest

from controller.executor import RELEASED_LIFTING, SkillExecutor
from controller.params import ExecutorParams
from interfaces.arm_auth import release_estop
from interfaces.messages import ControllerStatus, Estop, ServiceStatus
from runtime.config import ZenohSettings
from runtime.credentials import identity_folder
from runtime.session import ServiceNode

from .cell_harness import Cell
from .conftest import REPO
from .test_controller_units import BOARD, IdealArm, phases, run, stains
from .zenoh_helpers import free_port, wait_for, wait_sample, wait_subscribed

LAMPS = ("-m", "runtime.cli")
GOING = ("APPROACH", "WIPE", "TRANSITION", "RETREAT", "DONE")
#: Both sides released, the controller's status leaves ESTOP within this [s] (a status every 50 ms).
LEAVES_ESTOP_S = 0.5


def test_a_release_before_the_pad_is_off_lifts_it_paused_then_goes_on(learned_skill):
    """The robot side held the arm through the e-stop, so the skill's clock stood still and the stop's lift-off is
    still to run at the release: the executor is out of ESTOP at once (PAUSED while it lifts), then re-approaches."""
    ex = SkillExecutor(learned_skill, ExecutorParams())
    arm = IdealArm()
    ex.set_stains(BOARD, stains())
    for _ in range(30):
        run(ex, arm, 0.5)
        if ex.phase in ("WIPE", "TRANSITION") and ex.pad_down:
            break
    assert ex.phase in ("WIPE", "TRANSITION") and ex.pad_down, ex.phase
    ex.estop("button")
    for _ in range(3000):  # 3 s held by the robot side: the skill's step is 0
        arm.follow(ex.step(0.0, arm.tool))
    assert ex.phase == "ESTOP" and ex.pad_down
    ex.clear()
    assert (ex.phase, ex.reason) == ("PAUSED", RELEASED_LIFTING) and ex.pad_down
    log = run(ex, arm, 6.0)
    assert "ESTOP" not in phases(log) and phases(log)[:2] == ["PAUSED", "APPROACH"], phases(log)
    assert ex.phase in ("APPROACH", "WIPE", "TRANSITION")


@pytest.mark.slow
@pytest.mark.attack('4', "an operator's e-stop held 1 s and 3 s, then released (lock-step and real time)",
                    'ESTOP, then wiping again once both sides released')
@pytest.mark.parametrize("mode", ["lockstep", pytest.param("realtime", marks=pytest.mark.alone)])
def test_an_operator_estop_and_release_end_in_wiping_again(tmp_path, learned_skill_file, mode):
    with Cell(tmp_path / "run", learned_skill_file, mode) as cell:
        keys = cell.node.keys
        sim = cell.node.latest(keys.sim_status, ServiceStatus)
        for hold_s in (1.0, 3.0):
            cell.wait_phase(("WIPE",), 120.0, since=time.monotonic() - 0.5)
            t = time.monotonic()
            cell.node.publish(keys.controller_estop, Estop(stamp_ns=time.monotonic_ns(), engaged=True,
                                                           reason=f"test hold {hold_s} s", source="operator"))
            cell.wait_phase(("ESTOP",), 10.0, since=t)
            wait_sample(sim, lambda s: "estop=engaged" in s.detail, 10.0, "the robot side engaged")
            time.sleep(hold_s)
            t = time.monotonic()
            cell.node.publish(keys.controller_estop_release,
                              release_estop(cell.node.settings, "test release", "operator"))
            wait_sample(sim, lambda s: "estop=engaged" not in s.detail, 10.0, "the robot side released")
            resumed = cell.wait_phase(GOING, 30.0, since=t)
            assert resumed[1] != "ESTOP"
            time.sleep(1.0)
            assert cell.phases[-1][1] != "ESTOP", cell.phases[-6:]
        report = cell.finish()
    assert report["peak_contact_force_n"] <= report["force_cap_n"], report["peak_contact_force_n"]
    assert sum(1 for f in report["faults"] if f["phase"] == "ESTOP") >= 2, report["faults"]


def _linked_to(cell: Cell, service: str) -> ServiceNode:
    """An operator's session linked to ``service`` alone (gossip off; peers do not route for each other)."""
    return ServiceNode("operator", cell.operator_settings(connect=cell.services[service].listen_endpoints,
                                                          gossip=False))


@pytest.mark.slow
@pytest.mark.parametrize("order", ["robot side first", "controller first", "engaged on the robot side only",
                                   "engaged on the controller only"])
def test_whichever_side_hears_the_release_first_estop_ends_once_both_have(tmp_path, learned_skill_file, order):
    """Lock-step: the engage reaches both sides (or one), the release reaches one side 1 s before the other. ESTOP
    holds until the release that leaves neither side engaged, ends within ``LEAVES_ESTOP_S`` of it, and the
    controller wipes again with nothing latched."""
    with Cell(tmp_path / "run", learned_skill_file, "lockstep") as cell:
        keys = cell.node.keys
        with _linked_to(cell, "sim") as to_robot, _linked_to(cell, "controller") as to_controller:
            for node in (to_robot, to_controller):
                for key in (keys.controller_estop, keys.controller_estop_release):
                    wait_subscribed(node.session, key, timeout_s=40.0, what=f"{key} read")
            cell.wait_phase(("WIPE",), 120.0)
            engage = Estop(stamp_ns=time.monotonic_ns(), engaged=True, reason="test order", source="operator")
            t_engage = time.monotonic()
            for node, side in ((to_robot, "robot"), (to_controller, "controller")):
                if not order.endswith("only") or side in order:
                    node.publish(keys.controller_estop, engage)
            cell.wait_phase(("ESTOP",), 10.0, since=t_engage)
            time.sleep(1.5)
            release = release_estop(to_robot.settings, "test release", "operator")
            first, second = (to_controller, to_robot) if order == "controller first" else (to_robot, to_controller)
            t_first = time.monotonic()
            first.publish(keys.controller_estop_release, release)
            time.sleep(1.0)
            t_second = time.monotonic()
            second.publish(keys.controller_estop_release, release)
            t_both = t_first if order == "engaged on the robot side only" else t_second
            left = next(iter(wait_for(lambda: [e for e in cell.phases if e[0] > t_engage and e[1] != "ESTOP"], 10.0,
                                      f"out of ESTOP; phases {cell.phases[-4:]}")))
            print(f"{order}: out of ESTOP ({left[1]} {left[2]!r}) {left[0] - t_both:.2f} s after the release that "
                  "left neither side engaged")
            assert t_both <= left[0] < t_both + LEAVES_ESTOP_S, (t_first, t_second, cell.phases[-4:])
            cell.wait_phase(("WIPE", "TRANSITION"), 60.0, since=t_both)
            assert cell.status.counters["robot_estop_engaged"] == 0 and cell.status.counters["estop_latched"] == 0
            assert not [e for e in cell.phases if e[0] >= left[0] and e[1] == "ESTOP"], cell.phases[-6:]


def _port_base(n: int) -> int:
    """A port with ``n - 1`` free ports after it (lamps up --port-base; runtime/ports.py)."""
    return free_port(n)


def _drain(stream, lines: list[str]) -> None:
    for line in stream:
        lines.append(line)


@pytest.mark.slow
@pytest.mark.attack("4", "under lamps up, the operator's identity of the run folder engages the e-stop mid-wipe, "
                         "holds it 3 s and releases it (signed)",
                   "ESTOP left once both sides released, wiping again, the run cleaned")
def test_under_lamps_up_an_operators_estop_released_mid_wipe_ends_in_wiping_again_and_cleaned(tmp_path,
                                                                                          learned_skill_file):
    """``lamps up`` (lock-step) watched and stopped by the operator's tools: the operator's identity of the run
    folder engages the e-stop mid-wipe, holds it 3 s and releases it; the cell wipes again and lamps up ends with
    the board cleaned (not a run ended for an ESTOP that was over)."""
    out = tmp_path / "run"
    base = _port_base(3)
    proc = subprocess.Popen([sys.executable, *LAMPS, "up", "-q", "--out", str(out), "--port-base", str(base), "--skill",
                             str(learned_skill_file), "--max-duration", "400"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env={**os.environ, "MPLBACKEND": "Agg"}, cwd=REPO)
    lines: list[str] = []
    threading.Thread(target=_drain, args=(proc.stdout, lines), daemon=True).start()
    try:
        wait_for(lambda: any("running; run folder" in line for line in lines) or proc.poll() is not None, 180.0,
                 "lamps up's services running")
        assert proc.poll() is None, "".join(lines[-30:])
        settings = ZenohSettings(connect=tuple(f"tls/127.0.0.1:{base + i}" for i in range(3)), robot_id="iiwa",
                                 access_control=True, identity=str(identity_folder(out / "credentials", "operator")))
        with ServiceNode("operator", settings) as op:
            keys = op.keys
            status = op.latest(keys.controller_status, ControllerStatus)
            wait_sample(status, lambda s: s.phase == "WIPE", 180.0, "the controller wiping")
            t_engage = time.monotonic()
            op.publish(keys.controller_estop, Estop(stamp_ns=time.monotonic_ns(), engaged=True, reason="test hold 3 s",
                                                    source="operator"))
            wait_sample(status, lambda s: s.phase == "ESTOP", 10.0, "the controller in ESTOP")
            time.sleep(3.0 - (time.monotonic() - t_engage))
            t_release = time.monotonic()
            op.publish(keys.controller_estop_release, release_estop(op.settings, "test release", "operator"))
            left = wait_sample(status, lambda s: s.phase != "ESTOP", 10.0, "the controller out of ESTOP")
            t_left = time.monotonic()
            assert t_left - t_release < 1.0, (left.phase, left.reason)
            wait_sample(status, lambda s: s.phase == "WIPE", 60.0, "the controller wiping again")
            print(f"e-stop held {t_release - t_engage:.2f} s; out of ESTOP ({left.phase} {left.reason!r}) "
                  f"{t_left - t_release:.2f} s after the release, wiping again {time.monotonic() - t_release:.2f} s "
                  "after it")
        proc.wait(400)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
    assert proc.returncode == 0, "".join(lines[-40:])
    report = json.loads((out / "report.json").read_text())
    assert report["outcome"] == "cleaned", report["outcome"]
    assert any(f["phase"] == "ESTOP" and "test hold 3 s" in f["reason"] for f in report["faults"]), report["faults"]
