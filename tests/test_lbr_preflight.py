"""``lamps robot --backend lbr --preflight`` against the simulated stack over real Zenoh: all PASS on a stand-in set
up as docs/real-robot.md says, each wrong setting named with its fix on a wrong one; nothing is sent."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from robot.lbr.msgs import ConnectionQuality, LbrState, OperationMode, SessionState
from robot.lbr.params import LbrParams
from robot.lbr.preflight import Heard, judge

from .conftest import REPO
from .test_lbr_peer import TORQUE_SETUP, PeerProcess
from .zenoh_helpers import free_port, wait_alive

MS = 1_000_000


def _preflight(peer: PeerProcess, env: dict, *connect: int) -> subprocess.CompletedProcess:
    ends = [a for port in (peer.port, *connect) for a in ("--connect", f"tcp/127.0.0.1:{port}")]
    return subprocess.run([sys.executable, "-m", "robot.cli", "--backend", "lbr", "--preflight", *ends,
                           "--robot-id", peer.robot_id],
                          cwd=REPO, env=dict(os.environ, **env), capture_output=True, text=True, timeout=120)


def _lines(out: str) -> dict[str, str]:
    return {line.split(":")[0]: line for line in out.splitlines() if line.startswith(("PASS ", "FAIL "))}


@pytest.mark.slow
def test_the_preflight_passes_on_a_stand_in_set_up_for_torque_commands(tmp_path):
    peer_cfg = {**TORQUE_SETUP, "sample_time_s": 0.002, "mode": "realtime"}
    with PeerProcess(tmp_path, peer_cfg, ("--mode", "realtime")) as peer:
        listen = free_port()  # the watchdog beside the stack (peers do not route for each other: we reach it too)
        dog = subprocess.Popen([sys.executable, "-m", "robot.cli", "--backend", "lbr", "--watchdog", "--connect",
                                f"tcp/127.0.0.1:{peer.port}", "--listen", f"tcp/127.0.0.1:{listen}",
                                "--robot-id", peer.robot_id], cwd=REPO, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
        try:
            peer.tap.next(lambda st: st.session_state == SessionState.COMMANDING_ACTIVE, 30.0, "commanding")
            wait_alive(peer.node, "lbr-watchdog", 60.0)
            r = _preflight(peer, {"LAMPS__LBR__OPEN_LOOP": "false"}, listen)
            status = peer.status(None, "a peer status")
        finally:
            dog.send_signal(signal.SIGINT)
            dog.wait(20.0)
    print("\n" + r.stdout)
    lines = _lines(r.stdout)
    assert r.returncode == 0, r.stdout + r.stderr
    assert all(line.startswith("PASS") for line in lines.values()) and len(lines) == 12, lines
    assert status.counters.get("commands_received", 0) == 0, "the preflight sent something"


@pytest.mark.slow
def test_the_preflight_names_each_wrong_setting_with_its_fix(tmp_path):
    """The stack's open_loop default, the app in position control, AUT, a connection falling to POOR, the tool's
    load data left out; on our side a filter cutoff at the sample rate and the humble branch's joint names."""
    peer_cfg = {**TORQUE_SETUP, "sample_time_s": 0.001, "mode": "realtime", "open_loop": True,
                "control_mode": "position", "operation_mode": "AUT", "quality_drop_at_s": 0.01,
                "quality_step_s": 0.05, "quality_abort_after_s": 60.0, "tool_load_error_kg": 0.15}
    env = {"LAMPS__LBR__EXTERNAL_TORQUE_CUTOFF_HZ": "1000", "LAMPS__LBR__BRANCH": "humble"}
    with PeerProcess(tmp_path, peer_cfg, ("--mode", "realtime")) as peer:
        r = _preflight(peer, env)
    print("\n" + r.stdout)
    lines = _lines(r.stdout)
    assert r.returncode == 1, r.stdout + r.stderr
    failed = {name.split(" ", 1)[1] for name, line in lines.items() if line.startswith("FAIL")}
    assert failed == {"watchdog", "modes", "T1", "open_loop", "torque filter", "connection quality",
                      "joint names", "load data"}, r.stdout
    assert "control mode POSITION_CONTROL_MODE" in lines["FAIL modes"] and "JOINT_IMPEDANCE" in lines["FAIL modes"]
    assert "[lbr] open_loop = true" in lines["FAIL open_loop"] and "open_loop: false" in lines["FAIL open_loop"]
    assert "external_torque_cutoff_hz 1000 Hz" in lines["FAIL torque filter"]
    assert "POOR" in lines["FAIL connection quality"]
    assert "lbr_A1" in lines["FAIL joint names"] and "expects ['A1'" in lines["FAIL joint names"]
    assert "implies a tool of 0.30 kg" in lines["FAIL load data"] and "smartPAD" in lines["FAIL load data"]
    assert "failed: " in r.stdout


def _st(t_ms: int, **kw) -> LbrState:
    z = np.zeros(7)
    base = dict(sample_time_s=0.001, session_state=int(SessionState.COMMANDING_ACTIVE), safety_state=0,
                operation_mode=int(OperationMode.TEST_MODE_1), drive_state=2, client_command_mode=3, control_mode=2,
                stamp_ns=t_ms * MS, q_rad=z, tau_measured_nm=z, tau_external_nm=z, q_commanded_rad=z + 0.01,
                connection_quality=int(ConnectionQuality.EXCELLENT))
    return LbrState(**{**base, **kw})


def test_judge_names_a_frozen_clock_a_spring_preload_and_no_states():
    p = LbrParams(open_loop=False)
    names = list(p.joint_names)
    frozen = Heard([(i * MS, _st(5, q_commanded_rad=np.zeros(7) + 0.02)) for i in range(50)], "", names, True)
    checks = {c.name: c for c in judge(p, frozen)}
    assert not checks["robot clock"].ok and "advanced 0 times" in checks["robot clock"].seen
    assert not checks["spring preload"].ok and "joint spring 4.00 Nm" in checks["spring preload"].seen
    ok = Heard([(i * MS, _st(i, q_commanded_rad=np.zeros(7) + 0.001)) for i in range(50)], "", names, True, True)
    assert all(c.ok for c in judge(p, ok)), [c.line() for c in judge(p, ok) if not c.ok]
    none = judge(p, Heard([], "", None, False))
    assert [(c.name, c.ok) for c in none] == [("bridge", False), ("watchdog", False), ("states", False)]
    assert "lbr_torque_command_controller" in none[2].fix
