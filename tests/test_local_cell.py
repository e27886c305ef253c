"""The network-free cell: the in-process bus behind ServiceNode, and ``lamps up --no-network``'s refusals.

Whole network-free cells run in tests/test_campaign.py (a campaign's cells, compared with the Zenoh cell and
across a Ray cluster) and tests/test_launch.py (the adaptive streak).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from interfaces.config import ZenohSettings
from interfaces.local_bus import LocalBus, LocalNode
from interfaces.messages import Capabilities, Estop, RobotState, TorqueCommand

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
        # bytes that are not the key's message are counted and dropped by the same readers as on Zenoh
        bus.put(settings.keys.robot_state, b"\x93not a state")
        assert inbox.get(0.0) is None and sum(inbox.bad.values()) == 1 and inbox.received == 6
        assert len(everything) == 5
        # a TorqueCommand on the state key is refused as on the wire
        sim.publish(sim.keys.robot_state, TorqueCommand(seq=1, stamp_ns=1, tau_nm=[0.0] * 7))
        assert inbox.get(0.0) is None and sum(inbox.bad.values()) == 2
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
    r = subprocess.run([sys.executable, "-m", "interfaces.cli", "up", "--no-network", "--out", str(tmp_path / "r"),
                        *args], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert r.returncode == 1 and match in r.stderr, r.stderr
    assert not (tmp_path / "r").exists()
