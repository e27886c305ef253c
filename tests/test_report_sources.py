"""A report from a recording that stopped recording a key: right about the end of the run, and saying why.

Issue 46: the recording stopped at the disk budget while the cell went on, and the report said "incomplete,
69 %" of a board that was clean. Here, over a real Zenoh session pair, the controller's statuses and the sim's
truth outgrow their shares of a 1 MiB budget within the first second and are no longer recorded; the cell goes
on to DONE with 1 % of the dirt left. The recorder writes, at its close, the newest statuses and truth it kept
(what the services last said of themselves): the report says cleaned, 99 %, DONE, and that those figures come
from the services' own reports; no service is called silent for the recorder's gaps.
"""

from __future__ import annotations

import secrets
import time

from interfaces.messages import ControllerStatus, SimTruth
from launch.record import SELF_REPORTS_TOPIC, Recorder, read_recording
from launch.record_budget import SHUT
from launch.report import build_report
from runtime.config import ZenohSettings
from runtime.session import ServiceNode

from .zenoh_helpers import free_port, wait_for, wait_subscribed

RUN_S, WIPE_S, RATE_HZ = 4.0, 3.0, 20


def _status(i: int, phase: str) -> ControllerStatus:
    return ControllerStatus(seq=i, stamp_ns=i, phase=phase, wall_ns=time.time_ns(),
                            counters={secrets.token_hex(8): j for j in range(200)})  # hard to compress


def _truth(i: int, dirt: float) -> SimTruth:
    n = 2000
    return SimTruth(seq=i, stamp_ns=i, stain_ids=list(range(n)), remaining=[dirt / 100.0] * (n - 100) +
                    [float(x) / 256 for x in secrets.token_bytes(100)], total_dirt=dirt, contact_force_n=9.0,
                    robot_time_ns=i * 10**9 // RATE_HZ)


def _recorder_and_cell(tag: str) -> tuple[ServiceNode, ServiceNode]:
    """A recorder's node listening on a free loopback port and a cell's node connected to it (robot id tag+port)."""
    port = free_port()
    rid = f"{tag}{port}"
    rec_node = ServiceNode("recorder", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=rid)).__enter__()
    return rec_node, ServiceNode("cell", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=rid)).__enter__()


def test_past_their_shares_the_end_of_the_run_comes_from_the_services_own_reports(tmp_path):
    rec_node, cell = _recorder_and_cell("src")
    k = cell.keys
    try:
        rec = Recorder(rec_node.session, rec_node.keys, tmp_path, budget_bytes=1024**2)
        for key in (k.controller_status, k.sim_truth):
            wait_subscribed(cell.session, key)
        t0 = time.monotonic()
        for i in range(int(RUN_S * RATE_HZ)):
            t = i / RATE_HZ
            dirt = max(1.0, 100.0 - 99.0 * t / WIPE_S)
            cell.publish(k.controller_status, _status(i, "DONE" if t >= WIPE_S else "WIPE"))
            cell.publish(k.sim_truth, _truth(i, dirt))
            time.sleep(max(0.0, t0 + t + 1.0 / RATE_HZ - time.monotonic()))
        accounts = [rec.budget.account_of(key) for key in (k.controller_status, k.sim_truth)]
        wait_for(lambda: all(a.received == int(RUN_S * RATE_HZ) for a in accounts), 10.0, "every sample received")
        assert all(a.state == SHUT for a in accounts), [a.summary() for a in accounts]
        path = rec.close()
    finally:
        cell.close()
        rec_node.close()

    msgs = read_recording(path)
    (_, copies), = msgs[SELF_REPORTS_TOPIC]
    copied = {(c["key"], c["log_time_ns"]) for c in copies["messages"]}
    recorded = [m for t, m in msgs[k.sim_truth] if (k.sim_truth, t) not in copied]
    assert recorded[-1]["total_dirt"] > 50, "the recording of the truth stopped early"
    assert [m["phase"] for t, m in msgs[k.controller_status] if (k.controller_status, t) not in copied][-1] == "WIPE"

    report = build_report(tmp_path, keys=k, plots=False)
    assert (report["outcome"], report["final_phase"]) == ("cleaned", "DONE")
    assert abs(report["dirt_removed_fraction"] - 0.99) < 1e-9
    for figure in ("outcome", "final_phase", "dirt_removed_fraction", "sim_time_s", "counters"):
        assert report["sources"][figure]["from"] == "self-reports", (figure, report["sources"][figure])
        assert report["sources"][figure]["complete"] is False
    assert report["sources"]["max_contact_force_n"]["from"] == "recording"
    assert report["sources"]["dirt_removed_fraction"]["missing"]["sim/truth"] > 0
    assert report["recording"]["account"] == "final"
    assert report["recording"]["incomplete"] == ["controller/status", "sim/truth"]
    assert set(report["recording"]["self_reports"]) == {"controller/status", "sim/truth"}
    assert not [f for f in report["faults"] if f["phase"] == "SERVICE"], report["faults"]
    said = [f["reason"] for f in report["faults"] if f["phase"] == "RECORDER"]
    assert any("controller/status used its share" in r for r in said) and any("sim/truth used" in r for r in said)


def test_the_final_phase_is_what_the_controller_said_before_the_stop_not_when_the_recorder_heard_it(tmp_path):
    """A recorder that hears the controller late (the routed real-time cell on 2 cores: a background recorder 16 s
    behind its services) logs a DONE said before the launcher began stopping after that instant; the report reads
    the phase by the status's own wall time (a cell whose services share the launcher's clock) and says cleaned,
    not incomplete in the WIPE its log times would give. A network-free cell's log times are the robot's clock,
    as its stopping time is: there the log time still decides."""
    import json

    rec_node, cell = _recorder_and_cell("late")
    k = cell.keys
    try:
        rec = Recorder(rec_node.session, rec_node.keys, tmp_path)
        for key in (k.controller_status, k.sim_truth):
            wait_subscribed(cell.session, key)
        for i in range(5):
            cell.publish(k.controller_status, ControllerStatus(seq=i, stamp_ns=i, phase="WIPE", wall_ns=time.time_ns()))
            cell.publish(k.sim_truth, SimTruth(seq=i, stamp_ns=i, stain_ids=[0], remaining=[1.0 - 0.2 * i],
                                               total_dirt=100.0 - 20.0 * i, contact_force_n=9.0,
                                               robot_time_ns=i * 10**8))
        cell.publish(k.sim_truth, SimTruth(seq=5, stamp_ns=5, stain_ids=[0], remaining=[0.01], total_dirt=1.0,
                                           contact_force_n=0.0, robot_time_ns=5 * 10**8))
        account = rec.budget.account_of(k.controller_status)
        wait_for(lambda: account.received == 5, 10.0, "the WIPE statuses received")
        said = [ControllerStatus(seq=5 + i, stamp_ns=5 + i, phase="DONE", wall_ns=time.time_ns()) for i in range(3)]
        stopping_ns = time.time_ns()  # the launcher begins stopping here: the DONE statuses reach the recorder after
        time.sleep(0.3)
        for status in said:
            cell.publish(k.controller_status, status)
        wait_for(lambda: account.received == 8, 10.0, "every status received")
        rec.close()
    finally:
        cell.close()
        rec_node.close()

    logged = [t for t, m in read_recording(tmp_path / "recording.mcap")[k.controller_status] if m["phase"] == "DONE"]
    assert min(logged) > stopping_ns, "the DONE statuses must be heard after the stop for this test to mean anything"
    run = {"outcome": "done", "stopping_wall_ns": stopping_ns, "key_prefix": k.prefix}
    (tmp_path / "run.json").write_text(json.dumps(run))
    report = build_report(tmp_path, keys=k, plots=False)
    assert (report["final_phase"], report["outcome"]) == ("DONE", "cleaned"), report["final_phase"]
    assert abs(report["dirt_removed_fraction"] - 0.99) < 1e-9

    (tmp_path / "run.json").write_text(json.dumps({**run, "network": "none"}))
    assert build_report(tmp_path, keys=k, plots=False)["final_phase"] == "WIPE"
