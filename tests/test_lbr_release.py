"""What the stack does with the last message once nobody answers, under both damping laws of the robot's joint
impedance (robot/lbr/release.py): the simulated stack's FRI side and PID (sim/lbr_stack/stack.py) on the PyBullet
arm, in process; and the watchdog's rule (robot/lbr/watchdog.py)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from arm.robot_model import RobotModel
from robot.lbr.msgs import ClientCommandMode, SessionState, encode_torque_command
from robot.lbr.release import RELEASE_BYTES, RELEASE_JOINT_POSITION, RELEASE_TORQUE, is_release
from robot.lbr.watchdog import RELEASE_BURST, ReleaseWatch
from sim.core import SimCore
from sim.lbr_stack.params import LbrPeerParams
from sim.lbr_stack.stack import StackClient, StackError, impedance_damping, joint_impedance_torque
from sim.params import SimParams

T = 0.001  # the FRI period [s]
MS = 1_000_000


def _last_message(law: str, kind: str, seconds: float = 3.0, offset_rad: float = 0.02) -> dict:
    """The stack re-applying one message from the start: ``kind`` ``"hold"`` (a pose ``offset_rad`` off the arm's on
    A2 and A4, as for a pad pushed off a held pose; zero overlay) or ``"release"``; the robot's joint impedance
    (200 Nm/rad, ratio 0.7) under the damping ``law``. Returns the largest joint speed [rad/s] over the first and the
    last 0.5 s, and the stack's exit (its guard), if any."""
    sim = SimCore(SimParams.from_table({"camera": {"enabled": False}, "gravity_compensated": True}))
    model = RobotModel(joints=sim.joints)
    lim = model.limits
    stack = StackClient(LbrPeerParams.from_table({"sample_time_s": T, "client_command_mode": "torque",
                                                  "open_loop": False, "update_rate_hz": 1000}),
                        lim.q_min, lim.q_max, lim.dq_max)
    K = np.full(7, 200.0)
    q_hold = sim.out.q.copy()
    q_hold[[1, 3]] += offset_rad
    if kind == "hold":
        stack.receive(q_hold, np.zeros(7))
    else:
        stack.receive(RELEASE_JOINT_POSITION, RELEASE_TORQUE)
    n = round(seconds / T)
    speeds = np.zeros(n)
    prev = None
    out = {"exit": ""}
    try:
        for k in range(n):
            o = sim.out
            cmd = stack.fri_cycle(SessionState.COMMANDING_ACTIVE, o.q, o.q if prev is None else prev.joint_position,
                                  o.tau, np.zeros(7), ClientCommandMode.TORQUE, T, stamp_ns=k * MS)
            stack.cm_cycle()
            dq_cmd = (np.zeros(7) if prev is None or law == "absolute"
                      else (cmd.joint_position - prev.joint_position) / T)
            prev = cmd
            D = impedance_damping(K, 0.7, np.diag(pin.crba(model.model, model.data, o.q)).copy())
            sim.step(joint_impedance_torque(cmd.torque, cmd.joint_position, dq_cmd, o.q, o.dq, K, D))
            speeds[k] = float(np.max(np.abs(sim.out.dq)))
    except StackError as exc:
        out["exit"] = str(exc)
    finally:
        sim.close()
    half = round(0.5 / T)
    out["first"] = float(speeds[:half].max())
    out["last"] = float(speeds[-half:].max()) if not out["exit"] else float("inf")
    return out


@pytest.mark.slow
def test_a_frozen_hold_is_stable_only_under_relative_damping_and_the_release_under_both():
    """The hold a dead adapter leaves (a fixed target, zero overlay): the stack's PID integrates towards it around
    the robot's spring. Damping the commanded position's rate against the arm's, it settles; damping the arm's rate
    alone, A1..A4 oscillate ever wider (the stack's guard ends it, or the joints run away). The release (NaN joint
    position) has the stack re-initialise its command at the measured pose each cycle: nothing moves under either
    law."""
    hold_rel = _last_message("relative", "hold")
    hold_abs = _last_message("absolute", "hold")
    rel_rel = _last_message("relative", "release")
    rel_abs = _last_message("absolute", "release")
    print(f"\nfrozen hold: relative {hold_rel}, absolute {hold_abs}; release: relative {rel_rel}, absolute {rel_abs}")
    assert not hold_rel["exit"] and hold_rel["last"] < 0.1 * hold_rel["first"], hold_rel
    assert hold_abs["exit"] or hold_abs["last"] > 3.0 * hold_abs["first"], hold_abs
    for r in (rel_rel, rel_abs):
        assert not r["exit"] and r["first"] < 0.01 and r["last"] < 0.01, r


def test_the_release_is_nan_joint_positions_and_zero_torque_and_recognised_by_its_bytes():
    assert np.isnan(RELEASE_JOINT_POSITION).all() and not RELEASE_TORQUE.any()
    assert is_release(RELEASE_BYTES)
    assert not is_release(encode_torque_command(np.zeros(7), np.zeros(7)))


def test_the_watchdog_releases_after_a_silence_while_states_flow_and_stops_when_commands_resume():
    w = ReleaseWatch(0.2)
    hold = encode_torque_command(np.zeros(7), np.zeros(7))
    assert not w.state(0)  # nothing heard yet: an adapter not armed sends nothing
    w.command(hold, 1 * MS)
    assert not w.state(150 * MS)
    w.command(RELEASE_BYTES, 160 * MS)  # its own release is no command
    sent = [w.state(t * MS) for t in range(202, 202 + RELEASE_BURST + 3)]
    assert sent == [True] * RELEASE_BURST + [False] * 3
    assert w.state(320 * MS) and w.counts["release_episodes"] == 1
    w.command(hold, 400 * MS)  # an adapter back
    assert not w.releasing and not w.state(401 * MS) and w.counts["commands_resumed"] == 1
