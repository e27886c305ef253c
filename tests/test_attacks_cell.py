"""Attacks with a stolen identity against a whole cell (lock-step, the compose sim profile as local processes).

The thief holds perception's identity folder (its certificate and key: what a compromised perception box gives
away) and uses it the way the issue's attacker did: it *listens* on a port of its own and connects only to
perception's endpoint, so gossip makes the sim, the controller and the recorder open links to it (on a link a
service opened, user-password authentication names no remote, so a list keyed on user names cannot hold there;
certificates name both ends). Proof that the sim linked to it: it hears the sim's truth, which Zenoh peers do not
forward for others.
"""

from __future__ import annotations

import time

import pytest

from interfaces.codec import encode
from interfaces.messages import ControllerStatus, Estop, Pose, SimTruth, Stains, TorqueCommand
from runtime.session import ServiceNode

from .cell_harness import Cell
from .zenoh_helpers import free_port, wait_sample

pytestmark = pytest.mark.slow

FORGED_NM = 100.0


def _thief(cell: Cell) -> ServiceNode:
    settings = cell.operator_settings("perception", connect=cell.services["perception"].listen_endpoints,
                                      listen=(f"tls/127.0.0.1:{free_port()}",), access_control=False, gossip=True)
    return ServiceNode("perception-thief", settings)


@pytest.mark.attack("2, 3, 7", "with perception's stolen identity, one lock-step cell: a listening peer linked by "
                               "gossip replays the controller's captured commands, forges 100 Nm torques with its "
                               "session id and releases the e-stop for 3 s of wiping; once DONE, a Stains stream "
                               "places the board 10 m away (3 s at 20 Hz); the recording is checked for any of it",
                   "no forged command or release applied or recorded; the board cleaned, force and joint speeds "
                   "within limits; the jump not adopted: DONE held, no contact")
def test_a_thief_with_perceptions_identity_moves_nothing_is_not_recorded_and_cannot_move_the_board(
        tmp_path, learned_skill_file):
    with Cell(tmp_path / "run", learned_skill_file, "lockstep") as cell:
        keys = cell.node.keys
        cell.wait_phase(("WIPE",), 120.0)
        forced = _listening_thief_attacks(cell)
        assert cell.status is not None and cell.status.phase not in ("FAULT", "ESTOP"), cell.phases[-4:]
        cell.wait_phase(("DONE",), 180.0)
        worst = _board_jump_while_done(cell)
        report = cell.finish()
    assert worst < 0.5, worst
    assert report["final_phase"] == "DONE" and report["dirt_removed_fraction"] > 0.95, report["dirt_removed_fraction"]
    assert report["peak_contact_force_n"] <= report["force_cap_n"] and forced < 40.0
    assert report["max_joint_speed_ratio"] < 0.95, report["max_joint_speed_ratio"]
    from launch.record import read_recording

    rec = read_recording(tmp_path / "run" / "recording.mcap")
    commands = [m for _, m in rec.get(keys.robot_command, [])]
    assert commands, "the recorder records the controller's commands"
    assert max(max(abs(x) for x in m["tau_nm"]) for m in commands) < FORGED_NM, "no forged torque was recorded"
    assert not rec.get(keys.controller_estop_release), "no forged release was recorded"


def _listening_thief_attacks(cell: Cell) -> float:
    """Replays, forgeries and e-stop releases from a listening thief for 3 s; the largest true contact force [N]."""
    keys = cell.node.keys
    with _thief(cell) as thief:
        truth = thief.latest(keys.sim_truth, SimTruth)
        wait_sample(truth, timeout_s=15.0, what="the sim's truth at the thief: the sim opened a link to it")
        captured = thief.inbox(keys.robot_command, TorqueCommand, maxlen=5000)
        stolen: list[TorqueCommand] = []
        t_listen = time.monotonic() + 15.0  # lock-step runs as fast as a loaded host lets it: count, not seconds
        while len(stolen) <= 50 and time.monotonic() < t_listen:
            if (c := captured.get(0.1)) is not None:
                stolen.append(c)
        assert len(stolen) > 50, "the thief hears the controller's commands (every role may read)"
        session = stolen[-1].session
        forced, sent = 0.0, 0
        t_end = time.monotonic() + 3.0
        while time.monotonic() < t_end:
            for c in stolen[-20:]:  # replayed as they were captured
                thief.session.put(keys.robot_command, encode(c))
            forged = TorqueCommand(seq=stolen[-1].seq + sent + 1, stamp_ns=time.monotonic_ns(),
                                   tau_nm=[FORGED_NM] * 7, session=session)
            thief.session.put(keys.robot_command, encode(forged))
            thief.session.put(keys.controller_estop_release, encode(Estop(
                stamp_ns=time.monotonic_ns(), engaged=False, reason="forged", source="operator")))
            sent += 22
            if (t := truth.take()) is not None:
                forced = max(forced, t.contact_force_n)
            time.sleep(0.01)
        assert sent > 1000
    return forced


def _board_jump_while_done(cell: Cell) -> float:
    """A Stains stream placing the board 10 m away for 3 s while DONE; the largest true contact force [N] meanwhile."""
    keys = cell.node.keys
    with _thief(cell) as thief:
        real = wait_sample(thief.latest(keys.perception_stains, Stains), timeout_s=10.0, what="a real Stains")
        truth = thief.latest(keys.sim_truth, SimTruth)
        t = time.monotonic()
        p = real.T_board_to_world.position_m
        far = Pose([p[0] + 10.0, p[1], p[2]], real.T_board_to_world.quat_wxyz)
        worst = 0.0
        for i in range(60):
            fake = Stains(seq=real.seq + 1000 + i, stamp_ns=time.monotonic_ns(), T_board_to_world=far,
                          board_size_m=real.board_size_m, stains=real.stains, board="seen",
                          frame_seq=real.frame_seq + 1000 + i)
            thief.publish(keys.perception_stains, fake)
            if (tr := truth.take()) is not None:
                worst = max(worst, tr.contact_force_n)
            time.sleep(0.05)
        time.sleep(1.0)
        status = wait_sample(thief.latest(keys.controller_status, ControllerStatus), timeout_s=5.0)
        assert status.phase == "DONE", status
        assert [ph for tt, ph, _ in cell.phases if tt >= t] in ([], ["DONE"]), cell.phases[-4:]
    return worst
