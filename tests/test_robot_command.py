"""The robot side's tagged command (robot.command) and what a port says it did with a cycle (robot.port.Applied),
without a network: the gate's record, the ports' answers, the server's reading of them."""

from __future__ import annotations

from collections import Counter

import numpy as np

from interfaces.messages import HOLD, TORQUE, TorqueCommand
from robot.command import Command, CommandKind
from robot.gate import CommandGate
from robot.mock import MockArm
from robot.port import Applied
from robot.server import RobotServer, ServerParams
from runtime.local_bus import LocalBus, LocalNode


def test_a_command_is_a_reused_record_tagged_torque_or_hold():
    c = Command(3)
    buffer = c.tau_nm
    assert c.is_hold, "a new record holds: nothing to apply yet"
    assert c.set_torques(np.array([1.0, 2.0, 3.0])) is c and c.kind is CommandKind.TORQUE
    assert c.tau_nm is buffer and c.tau_nm.tolist() == [1.0, 2.0, 3.0], "copied into its own buffer"
    kept = Command(3).assign(c)
    assert kept.kind is CommandKind.TORQUE and kept.tau_nm.tolist() == [1.0, 2.0, 3.0]
    c.set_hold()
    assert c.is_hold and kept.kind is CommandKind.TORQUE, "a copy does not follow the original"
    assert Command(3).set_torques(np.ones(3)).assign(c).is_hold


def test_the_gate_reads_the_wire_mode_into_its_one_record():
    gate = CommandGate(np.full(2, 10.0), Counter())
    torques = gate.check(TorqueCommand(seq=0, stamp_ns=0, tau_nm=[20.0, -1.0], mode=TORQUE))
    assert torques is gate.command and torques.kind is CommandKind.TORQUE and torques.tau_nm.tolist() == [10.0, -1.0]
    held = gate.accept(TorqueCommand(seq=1, stamp_ns=0, tau_nm=[], mode=HOLD))
    assert held is gate.command and held.is_hold, "the same record, reused by the next call"


def test_the_ports_say_what_they_did():
    arm = MockArm()
    assert arm.write(np.ones(7)) is Applied.TORQUES
    assert arm.hold() is Applied.HELD
    # the defaults: the port's own hold, and what it did
    assert arm.estop_hold() is Applied.HELD and arm.speed_hold() is Applied.HELD
    assert arm.yield_hold(np.zeros(7)) is Applied.HELD
    assert [a for a in Applied if a.took_command] == [Applied.TORQUES, Applied.DISARMED]


class DisarmedArm(MockArm):
    """A mock arm not commanding its robot: it takes each command without applying it."""

    def write(self, tau_nm: np.ndarray) -> Applied:
        self.hold()
        return Applied.DISARMED


def _cycles(arm: MockArm, modes: list[str]) -> list[tuple[Applied, bool, int]]:
    """Lock-step cycles of 1 Nm commands (or holds) on ``arm``: the server's (outcome, braked, applied_seq) after
    each."""
    with LocalNode("robot", LocalBus()) as node:
        srv = RobotServer(arm, node, ServerParams(mode="lockstep"), "robot", node.keys.robot_status)
        srv.start_lockstep()
        out = []
        for seq, mode in enumerate(modes):
            assert srv.lockstep_cycle(TorqueCommand(seq=seq, stamp_ns=0, tau_nm=[1.0] * 7, mode=mode))
            out.append((srv.cycle.outcome, srv.cycle.braked, srv.cycle.applied_seq))
    return out


def test_the_server_takes_what_the_port_did_for_what_the_state_reports():
    assert _cycles(MockArm(), [TORQUE, HOLD, TORQUE]) == [(Applied.TORQUES, False, 0), (Applied.HELD, True, -1),
                                                          (Applied.TORQUES, False, 2)]
    # a port that took the command without sending it: the server serves on as after torques
    assert _cycles(DisarmedArm(), [TORQUE, HOLD]) == [(Applied.DISARMED, False, 0), (Applied.HELD, True, -1)]
