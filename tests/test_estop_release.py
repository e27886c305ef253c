"""An operator's e-stop and its release over the whole cell: the arm lifts off and holds, then wipes on.

The compose cell's sim profile as local processes with access control
(:mod:`tests.cell_harness`), lock-step and real time. While the pad wipes,
the operator engages the e-stop on ``controller/estop`` and, after a hold of
1 s or 3 s, releases it on ``controller/estop/release``; the robot side and
the controller both hear both. Once both have released, the controller must
leave ESTOP and go on (re-approach, wipe, retreat): never stay latched
waiting for a release that has already happened.
"""

from __future__ import annotations

import time

import pytest

from interfaces.messages import Estop, ServiceStatus

from .cell_harness import Cell
from .zenoh_helpers import wait_sample

pytestmark = pytest.mark.slow

GOING = ("APPROACH", "WIPE", "TRANSITION", "RETREAT", "DONE")


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
            cell.node.publish(keys.controller_estop_release, Estop(stamp_ns=time.monotonic_ns(), engaged=False,
                                                                   reason="test release", source="operator"))
            wait_sample(sim, lambda s: "estop=engaged" not in s.detail, 10.0, "the robot side released")
            resumed = cell.wait_phase(GOING, 30.0, since=t)
            assert resumed[1] != "ESTOP"
            time.sleep(1.0)
            assert cell.phases[-1][1] != "ESTOP", cell.phases[-6:]
        report = cell.finish()
    assert report["peak_contact_force_n"] <= report["force_cap_n"], report["peak_contact_force_n"]
    assert sum(1 for f in report["faults"] if f["phase"] == "ESTOP") >= 2, report["faults"]
