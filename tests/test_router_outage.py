"""A cell whose every service is a client of ``lamps router``, with the router killed mid-wipe and started again.

All routes go at once: in lock-step nothing moves while the router is gone (the robot side waits for the
command of its state), every client reconnects to the same endpoint on its own (Zenoh's connect retry), the
controller, having lost the robot, lifts the pad off before it re-approaches, and the cell wipes on to a clean
board, forces and speeds within their limits. Over real Zenoh, mutual TLS and the
access lists; real PyBullet, Pinocchio and perception.
"""

from __future__ import annotations

import time

import pytest

from .cell_harness import Cell
from .test_faults import GOING, assert_safe, fault_reasons, wait_done_for_good
from .zenoh_helpers import wait_sample

pytestmark = pytest.mark.slow


@pytest.mark.attack('faults', 'the router every service is a client of killed mid-wipe for 3 s, lock-step',
                    'nothing moves while it is gone; every client reconnects; the board cleaned, within limits')
def test_a_cell_through_the_router_wipes_on_after_the_router_died_and_came_back(tmp_path, learned_skill_file):
    from interfaces.messages import SimTruth

    with Cell(tmp_path / "run", learned_skill_file, "lockstep", router=True) as cell:
        cell.wait_phase(("WIPE",), 120.0)
        time.sleep(1.0)
        truth = cell.node.latest(cell.node.keys.sim_truth, SimTruth)
        # the watching client follows the cell through the router before it goes (its subscription reaches the
        # publisher over the router: on a loaded machine that takes a while)
        wait_sample(truth, None, 30.0, "the simulator's truth through the router")
        cell.restart("router", down_s=3.0)  # SIGKILL: every service loses every route at once, for 3 s
        cell.wait_phase(GOING, 60.0, since=time.monotonic() - 1.0)
        wait_done_for_good(cell, 240.0)
        report = cell.finish()
    assert_safe(report)
    assert report["dirt_removed_fraction"] >= 0.98, report["dirt_removed_fraction"]
    reasons = [f["reason"] for f in report["faults"]]
    assert not any("exited" in r for r in fault_reasons(report, "SERVICE")), reasons  # no service died of the outage
    # the controller lost the robot (lock-step: the robot side waited for it), and lifted the pad on its return;
    # its status saying so may go unrecorded (the recorder, a client of the same router, may reconnect after the
    # robot side: "nothing recorded for 7.1 s"), its counter does not
    assert report["counters"]["controller"].get("robot_lost", 0) >= 1, (report["counters"]["controller"], reasons)
    assert any(r.startswith("robot back with the pad on the board") for r in reasons), reasons
