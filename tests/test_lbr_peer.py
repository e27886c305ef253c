"""The lbr peer (the stack simulated): its parts without a network, then ``lamps lbr-peer`` as a process against a
raw CDR client.

The client is what our real-robot adapter will be: a Zenoh session on the
bridge keys (``lbr/state`` in, ``lbr/command/torque`` out) decoding and
encoding CDR with :mod:`robot.lbr.msgs`, and the cell's keys for the
status and the truth.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest

from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from interfaces.messages import ServiceStatus, SimTruth
from robot.lbr import msgs
from robot.lbr.msgs import SessionState
from runtime.config import ZenohSettings
from runtime.session import ServiceNode
from sim.lbr_stack.commands import TORQUE_COMMAND_BYTES, CommandBox, drop_reason
from sim.lbr_stack.fri_robot import external_torque_nm
from sim.lbr_stack.params import LbrPeerParams
from sim.lbr_stack.peer import sim_params_for_peer, substeps_for_peer

from .conftest import REPO
from .zenoh_helpers import free_port, toml_value, wait_alive, wait_for, wait_sample, wait_subscribed, write_config

READY, WAIT, ACTIVE = SessionState.MONITORING_READY, SessionState.COMMANDING_WAIT, SessionState.COMMANDING_ACTIVE
MS = 1_000_000


# -- configuration ------------------------------------------------------------------------------------------

def test_the_example_config_shows_the_defaults():
    example = tomllib.loads((REPO / "config" / "example.toml").read_text())
    assert LbrPeerParams.from_table(example["lbr_peer"]) == LbrPeerParams()
    p = LbrPeerParams()
    assert (p.namespace, p.mode, p.sample_time_s, p.operation_mode, p.joint_stiffness_nm_rad) == \
        ("lbr", "lockstep", 0.001, "T1", 200.0)
    # the stack's own defaults (lbr_system_config.yaml, lbr_controllers.yaml, LBRServer.java)
    assert (p.client_command_mode, p.open_loop, p.update_rate_hz, p.pid_p, p.fri_major, p.branch) == \
        ("position", True, 100.0, 0.1, 1, "rolling")
    assert (p.measured_torque_cutoff_hz, p.external_torque_cutoff_hz, p.ft_force_threshold_n) == (10.0, 10.0, 2.0)
    assert p.cm_every == 10 and LbrPeerParams(update_rate_hz=500.0, sample_time_s=0.002).cm_every == 1
    humble = LbrPeerParams(branch="humble")  # humble's lbr_controllers.yaml: 200 Hz; its wrench every cycle
    assert (humble.update_rate_hz, humble.ft_update_rate_hz, p.ft_update_rate_hz) == (200.0, 200.0, 100.0)


@pytest.mark.parametrize("table, match", [
    ({"mode": "warp"}, r"\[lbr_peer\] mode must be one of"),
    ({"namespace": "a b"}, r"\[lbr_peer\] namespace"),
    ({"namespace": "lbr/*"}, r"\[lbr_peer\] namespace"),
    ({"sample_time_s": 0.1}, r"\[lbr_peer\] sample_time_s must be a number in \[0.001, 0.01\]"),
    ({"fri_major": 3}, r"\[lbr_peer\] fri_major must be one of \(1, 2\)"),
    ({"branch": "foxy"}, r"\[lbr_peer\] branch must be one of"),
    ({"client_command_mode": "cartesian"}, r"\[lbr_peer\] client_command_mode must be one of"),
    ({"open_loop": "no"}, r"\[lbr_peer\] open_loop must be true or false"),
    ({"operation_mode": "AUTO"}, r"\[lbr_peer\] operation_mode must be one of \('T1', 'T2', 'AUT'\)"),
    ({"ft_update_rate_hz": 2000.0}, r"\[lbr_peer\] ft_update_rate_hz"),
    ({"joint_stiffness_nm_rad": -1.0}, r"\[lbr_peer\] joint_stiffness_nm_rad"),
    ({"stop_app_after_s": True}, r"\[lbr_peer\] stop_app_after_s"),
    ({"stiffness": 3.0}, r"\[lbr_peer\] unknown key\(s\) \['stiffness'\]"),
])
def test_bad_peer_config_is_refused_with_the_key_named(table, match):
    with pytest.raises(ConfigError, match=match):
        LbrPeerParams.from_table(table)


def test_the_arm_is_gravity_compensated_and_each_fri_cycle_is_whole_physics_steps():
    p = LbrPeerParams(sample_time_s=0.002, mode="realtime", namespace="/robots/lbr/")
    sim = sim_params_for_peer({"gravity_compensated": False, "seed": 3}, p)
    assert sim.gravity_compensated and sim.rate_hz == 1000.0 and sim.mode == "realtime" and sim.seed == 3
    assert substeps_for_peer(sim, p) == 2, "FRI 2 ms over 1 ms physics: each command held for two steps"
    with pytest.raises(ConfigError, match="whole number of the sim's physics steps"):
        substeps_for_peer(sim, LbrPeerParams(sample_time_s=0.0015))
    assert p.namespace == "robots/lbr" and p.robot_name == "lbr"
    assert p.topics.key(p.topics.state) == "robots/lbr/state"


# -- the external torque -------------------------------------------------------

def test_external_torque_is_the_virtual_work_of_the_wrench_by_finite_differences():
    """tau_i = f . dp/dq_i + m . dtheta/dq_i at the TCP, world axes (J^T w without using J)."""
    model = RobotModel()
    rng = np.random.default_rng(0)
    q = np.array([0.5, 0.3, -0.6, -1.9, -0.1, -0.6, -1.2])
    w = rng.normal(size=6) * np.array([10, 10, 10, 1, 1, 1])
    tau = external_torque_nm(model.tcp_jacobian(q), w)
    eps = 1e-6
    p0, R0 = model.tcp_pose(q)
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = eps
        p1, R1 = model.tcp_pose(q + dq)
        dR = R1 @ R0.T
        dtheta = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]]) / 2
        assert tau[i] == pytest.approx((w[:3] @ (p1 - p0) + w[3:] @ dtheta) / eps, abs=1e-4)


def test_dropped_commands_are_classified_by_reason():
    good = msgs.encode_torque_command(np.zeros(7), np.ones(7))
    assert len(good) == TORQUE_COMMAND_BYTES

    def reason(raw):
        with pytest.raises(msgs.LbrWireError) as exc:
            msgs.decode_torque_command(raw)
        return drop_reason(raw, exc.value)

    six = good[:4] + np.zeros(12).tobytes()  # a sender with float64[6] arrays
    nan = msgs.encode_torque_command(np.zeros(7), np.array([0, 0, np.nan, 0, 0, 0, 0]))
    assert [reason(r) for r in (b"garbage", b"", six, good[:60], nan)] == \
        ["not_cdr", "not_cdr", "wrong_length", "wrong_length", "non_finite"]


@pytest.mark.parametrize("channel", [False, True], ids=["callback (lock-step)", "ring channel (real time)"])
def test_the_command_box_keeps_the_newest_valid_command_and_counts_the_bad_ones(channel):
    """Over a real Zenoh session pair: valid commands in order, the newest taken, garbage and NaN counted by
    reason; the real-time box takes its samples from Zenoh's ring without a Python callback."""
    port = free_port()
    listen = ServiceNode("test-listen", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",))).__enter__()
    talk = ServiceNode("test-talk", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",))).__enter__()
    key = "lbr/command/torque"
    box = CommandBox(listen.session, key, maxlen=8, channel=channel)
    try:
        wait_subscribed(talk.session, key)
        nan = np.zeros(7)
        nan[2] = np.nan
        for raw in (msgs.encode_torque_command(np.zeros(7), np.full(7, 1.0)), b"garbage",
                    msgs.encode_torque_command(np.zeros(7), nan),
                    msgs.encode_torque_command(np.zeros(7), np.full(7, 2.0))):
            talk.session.put(key, raw)
        if channel:
            with pytest.raises(RuntimeError, match="callback box"):
                box.get(0.1)
        # the callback box fills by itself; the ring is drained by the loop's own calls, in as many as it takes
        taken, valid = None, 0
        deadline = time.monotonic() + 5.0
        while box.counters()["commands_received"] < 4 and time.monotonic() < deadline:
            if channel:
                command, superseded = box.newest()
                if command is not None:
                    taken, valid = command, valid + 1 + superseded
            time.sleep(0.01)
        if not channel:
            taken, superseded = box.newest()
            valid = 1 + superseded
        assert taken is not None and taken[1].tolist() == [2.0] * 7 and valid == 2, (taken, valid)
        c = box.counters()
        assert c["commands_received"] == 4 and c["commands_dropped_not_cdr"] == 1 \
            and c["commands_dropped_non_finite"] == 1, c
        assert box.newest() == (None, 0)
    finally:
        box.close()
        talk.close()
        listen.close()


# -- the command line ---------------------------------------------------------------------------------------

def test_check_names_the_keys_and_a_bad_config_is_one_line(tmp_path, capsys):
    from sim.lbr_stack import cli as peer_cli

    path = tmp_path / "ok.toml"
    path.write_text('[lbr_peer]\nnamespace = "arm1"\n[sim.camera]\nenabled = false\n')
    assert peer_cli.main(["--config", str(path), "--check", "--mode", "realtime"]) == 0
    out = capsys.readouterr().out
    assert "arm1/state" in out and "arm1/command/torque" in out and "mode realtime" in out
    bad = tmp_path / "bad.toml"
    bad.write_text("[lbr_peer]\nupdate_rate_hz = -1.0\n")
    assert peer_cli.main(["--config", str(bad), "--check"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[lbr_peer] update_rate_hz" in err
    with pytest.raises(SystemExit) as exc:
        peer_cli.main(["--mode", "warp"])
    assert exc.value.code == 2


def test_lbr_peer_is_a_lamps_command():
    from runtime.cli import COMMANDS

    assert COMMANDS["lbr-peer"][0] == "sim.lbr_stack.cli:main"


# -- the peer as a process ----------------------------------------------------------------------------------

class StateTap:
    """Every ``LBRState`` on a key, decoded, in arrival order; :meth:`next` waits for one that is accepted."""

    def __init__(self, session, key: str) -> None:
        self.states: list[msgs.LbrState] = []
        self._cursor = 0
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample) -> None:
        state = msgs.decode_state(sample.payload.to_bytes(), msgs.state_layout(sample.payload.to_bytes()) or 1)
        with self._cond:
            self.states.append(state)
            self._cond.notify_all()

    def next(self, accept=None, timeout_s: float = 5.0, what: str = "a state") -> msgs.LbrState:
        """The first state after the last one taken for which ``accept(state)`` holds (earlier ones skipped)."""
        end = time.monotonic() + timeout_s
        with self._cond:
            while True:
                while self._cursor < len(self.states):
                    state = self.states[self._cursor]
                    self._cursor += 1
                    if accept is None or accept(state):
                        return state
                if not self._cond.wait(max(end - time.monotonic(), 0.0)) and time.monotonic() >= end:
                    raise AssertionError(f"{what} not received within {timeout_s} s")

    def skip_all(self) -> None:
        with self._cond:
            self._cursor = len(self.states)

    def close(self) -> None:
        self._sub.undeclare()


class PeerProcess:
    """``lamps lbr-peer`` in its own process, a client node connected to it, a tap on its states."""

    def __init__(self, tmp_path: Path, peer: dict, args: tuple[str, ...] = (), namespace: str = "lbr") -> None:
        self.port = free_port()
        self.robot_id = f"t{self.port}"
        self.config = write_config(tmp_path / "peer.toml", self.port, self.robot_id, {"camera": {"enabled": False}})
        with self.config.open("a") as f:
            f.write("\n[lbr_peer]\n" + "".join(f"{k} = {toml_value(v)}\n" for k, v in peer.items()))
        self.args = args
        self.topics = msgs.LbrTopics(namespace)

    def __enter__(self) -> PeerProcess:
        self.proc = subprocess.Popen([sys.executable, "-m", "sim.lbr_stack.cli", "--config", str(self.config),
                                      *self.args], cwd=REPO, env=dict(os.environ, PYTHONUNBUFFERED="1"),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        settings = ZenohSettings(connect=(f"tcp/127.0.0.1:{self.port}",), robot_id=self.robot_id)
        self.node = ServiceNode("test-client", settings).__enter__()
        try:
            self.tap = StateTap(self.node.session, self.key(self.topics.state))
            wait_alive(self.node, "lbr-peer", 60.0)
            wait_subscribed(self.node.session, self.key(self.topics.torque_command), 30.0,
                            "the peer's command subscriber")
            self.commands = self.node.session.declare_publisher(self.key(self.topics.torque_command))
        except BaseException:
            self.__exit__()
            raise
        return self

    def key(self, topic: str) -> str:
        return self.topics.key(topic)

    def send(self, q_rad, tau_nm) -> None:
        self.commands.put(msgs.encode_torque_command(np.asarray(q_rad, float), np.asarray(tau_nm, float)))

    def status(self, accept=None, what: str = "a peer status") -> ServiceStatus:
        reader = self.node.latest(self.node.keys.sim_status, ServiceStatus)
        try:
            return wait_sample(reader, accept, 10.0, what)
        finally:
            reader.close()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(20.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                raise AssertionError("lamps lbr-peer did not stop on SIGINT") from None
        return self.proc.returncode

    def __exit__(self, *exc) -> None:
        try:
            self.stop()
        finally:
            self.node.close()


def every_fri_cycle(stamps_ns: np.ndarray) -> bool:
    """Stamps 1 ms apart on the robot's clock (a sample the loopback dropped under load leaves a 2 ms gap)."""
    d = np.diff(stamps_ns)
    return len(d) > 10 and bool(np.all(d > 0) and np.all(d % MS == 0) and np.mean(d == MS) > 0.95)


def _start_pose() -> np.ndarray:
    from sim.board import board_from_params, start_configuration
    from sim.params import BoardParams, SimParams

    return start_configuration(board_from_params(BoardParams()), SimParams().start_standoff_m)


#: The stack as docs/real-robot.md has a user set it up for torque commands; the rest stays the stack's default.
TORQUE_SETUP = {"client_command_mode": "torque", "open_loop": False, "update_rate_hz": 1000.0}


@pytest.mark.slow
def test_lockstep_peer_holds_the_joint_spring_and_reapplies_the_last_command_forever(tmp_path):
    peer_cfg = {**TORQUE_SETUP, "mode": "lockstep", "commanding_after_s": 0.5, "lockstep_wait_s": 0.2,
                "status_rate_hz": 20.0}
    with PeerProcess(tmp_path, peer_cfg) as peer:
        wrenches, joint_states = [], []
        session = peer.node.session
        subs = [session.declare_subscriber(peer.key(peer.topics.wrench),
                                           lambda s: wrenches.append(msgs.decode_wrench(s.payload.to_bytes()))),
                session.declare_subscriber(peer.key(peer.topics.joint_states),
                                           lambda s: joint_states.append(s.payload.to_bytes()))]
        truth = peer.node.latest(peer.node.keys.sim_truth, SimTruth)
        # nothing is published before COMMANDING_WAIT (system_interface.cpp:249-265)
        first = peer.tap.next(timeout_s=20.0, what="the first state")
        assert first.session_state in (WAIT, ACTIVE) and first.stamp_ns >= 500 * MS
        assert first.sample_time_s == 0.001 and (first.client_command_mode, first.control_mode) == (3, 2)
        np.testing.assert_allclose(first.q_rad, _start_pose(), atol=1e-3)

        # garbage, wrong lengths and NaN are counted and dropped
        peer.commands.put(b"garbage")
        peer.commands.put(msgs.encode_torque_command(np.zeros(7), np.zeros(7))[:60])
        peer.send(first.q_rad, [0, 0, np.nan, 0, 0, 0, 0])
        peer.status(lambda m: m.counters.get("commands_dropped_non_finite", 0) >= 1
                    and m.counters.get("commands_dropped_not_cdr", 0) >= 1
                    and m.counters.get("commands_dropped_wrong_length", 0) >= 1, "the bad commands counted")

        # a frozen target and +0.5 Nm on A1 (a vertical axis) each state: the robot's joint spring (200 Nm/rad)
        # and the stack's PID pull A1 back onto the target; the stack's command settles 0.5 / 200 rad behind
        target = np.array(first.q_rad)
        state = peer.tap.next(lambda s: s.session_state == ACTIVE, 10.0, "COMMANDING_ACTIVE")
        seen = []
        for k in range(1500):
            peer.send(target, [0.5, 0, 0, 0, 0, 0, 0])
            state = peer.tap.next(lambda s, t=state.stamp_ns: s.stamp_ns > t, what=f"the state after command {k}")
            seen.append(state)
        q = np.array([s.q_rad for s in seen])
        c = np.array([s.q_commanded_rad for s in seen])
        assert np.ptp(q[:, 0]) > 1e-4, "the overlay moved A1 at first"
        assert abs(q[-1, 0] - target[0]) < 2e-4, q[-1, 0] - target[0]
        assert c[-1, 0] - target[0] == pytest.approx(-0.5 / 200.0, abs=3e-4)
        assert seen[-1].tau_external_nm is not None and max(abs(s.tau_external_nm).max() for s in seen) < 1e-6

        # silence: the robot runs on (no watchdog), the stack re-applying the last message: still ACTIVE, the
        # overlay still commanded
        last = seen[-1]
        later = peer.tap.next(lambda s: s.stamp_ns > last.stamp_ns + 500 * MS, 10.0, "0.5 s of robot time on")
        assert later.session_state == ACTIVE
        status = peer.status(lambda m: m.counters.get("lockstep_answers_missed", 0) >= 1, "the answer missed")
        assert status.counters["stack_up"] == 1 and status.counters["session_state"] == int(ACTIVE)
        raw = []
        sub = session.declare_subscriber(peer.key(peer.topics.state), lambda s: raw.append(s.payload.to_bytes()))
        wait_for(lambda: len(raw) > 5, 10.0, "more states")
        sub.undeclare()
        commanded = msgs.TYPESTORE.deserialize_cdr(raw[-1], msgs.STATE_TYPE).commanded_torque
        assert commanded[0] == 0.5, commanded

        assert wrenches and all(f == "lbr_link_ee" for f, _ in wrenches)
        assert joint_states and msgs.decode_joint_names(joint_states[-1]) == tuple(f"lbr_A{i}" for i in range(1, 8))
        assert wait_sample(truth, timeout_s=5.0, what="sim/truth").stain_ids
        for s_ in subs:
            s_.undeclare()
        assert peer.stop() == 0


@pytest.mark.slow
@pytest.mark.alone
def test_realtime_open_loop_publishes_the_stacks_command_and_the_stack_exits_when_commanding_ends(tmp_path):
    """The stack's defaults but the torque mode: open_loop publishes its own command as measured
    (async_client.cpp:82-85), bitwise equal to the robot's commanded position, frozen while an overlay moves the arm;
    when the operator stops the app the stack exits (system_interface.cpp:307-318): no more states."""
    peer_cfg = {"client_command_mode": "torque", "update_rate_hz": 1000.0, "stop_app_after_s": 5.0,
                "status_rate_hz": 20.0, "branch": "humble", "fri_major": 2}
    with PeerProcess(tmp_path, peer_cfg, ("--mode", "realtime", "--namespace", "arm2"), namespace="arm2") as peer:
        answering = threading.Event()
        answering.set()

        def answer(sample):  # what an adapter does: answer each state as it comes
            if answering.is_set():
                st = msgs.decode_state(sample.payload.to_bytes(), 2)
                peer.send(st.q_rad, [2.0, 0, 0, 0, 0, 0, 0])

        sub = peer.node.session.declare_subscriber(peer.key(peer.topics.state), answer)
        active = peer.tap.next(lambda s: s.session_state == ACTIVE, 10.0, "COMMANDING_ACTIVE")
        assert active.q_commanded_rad is None  # the FRI 2 layout
        later = peer.tap.next(lambda s: s.stamp_ns > active.stamp_ns + 500 * MS, 10.0, "0.5 s of commanding")
        frozen = [s.q_rad for s in peer.tap.states if active.stamp_ns + 100 * MS <= s.stamp_ns <= later.stamp_ns]
        assert len(frozen) > 100 and all(np.array_equal(f, frozen[0]) for f in frozen), "the published position"
        status = wait_sample(peer.node.latest(peer.node.keys.sim_status, ServiceStatus),
                             lambda m: m.counters.get("stack_up") == 0, 15.0, "the stack exiting")
        assert "stack exited: LBR left COMMANDING_ACTIVE" in status.detail, status.detail
        answering.clear()
        n = len(peer.tap.states)
        time.sleep(0.3)
        assert len(peer.tap.states) == n, "states after the stack exited"
        assert max(s.stamp_ns for s in peer.tap.states) <= 5000 * MS + 2 * MS
        assert 1500 < status.counters["spring_max_mnm"] < 2600  # the arm moved ~10 mrad off the frozen command
        sub.undeclare()
        assert peer.stop() == 0
