"""Two real Zenoh peers on loopback (multicast off, explicit endpoints, free ports)."""

from __future__ import annotations

import time

import pytest

from interfaces.codec import encode
from interfaces.messages import Capabilities, Estop, RobotState, ServiceStatus, TorqueCommand
from runtime.config import ZenohSettings
from runtime.session import ServiceNode, publisher_qos

from .zenoh_helpers import free_port, wait_alive, wait_for, wait_gone, wait_sample, wait_subscribed


@pytest.fixture()
def peers():
    port = free_port()
    robot = f"t{port}"
    a = ServiceNode("sim", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=robot))
    b = ServiceNode("controller", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=robot))
    with a, b:
        wait_alive(b, "sim")
        yield a, b


def state(seq: int) -> RobotState:
    return RobotState(seq=seq, stamp_ns=time.monotonic_ns(), q_rad=[0.1 * seq] * 7, dq_rad_s=[0.0] * 7,
                      tau_nm=[0.0] * 7, wrench_world=[0.0] * 6, capabilities=Capabilities(False, [100.0] * 7))


def test_messages_cross_between_two_peers(peers):
    sim, ctrl = peers
    states = ctrl.latest(ctrl.keys.robot_state, RobotState)
    commands = sim.latest(sim.keys.robot_command, TorqueCommand)
    wait_subscribed(sim.session, sim.keys.robot_state)
    wait_subscribed(ctrl.session, ctrl.keys.robot_command)
    sim.publish(sim.keys.robot_state, state(1))
    got = wait_for(states.take)
    assert got.seq == 1 and got.q_rad == state(1).q_rad and got.capabilities == state(1).capabilities
    ctrl.publish(ctrl.keys.robot_command, TorqueCommand(seq=got.seq, stamp_ns=1, tau_nm=[0.5] * 7))
    cmd = wait_for(commands.take)
    assert cmd.seq == 1 and cmd.tau_nm == [0.5] * 7
    assert states.take() is None  # taken once


def test_the_reader_keeps_only_the_newest_sample(peers):
    sim, ctrl = peers
    states = ctrl.latest(ctrl.keys.robot_state, RobotState)
    wait_subscribed(sim.session, sim.keys.robot_state)
    for seq in range(1, 51):
        sim.publish(sim.keys.robot_state, state(seq))
    seen = []

    def newest_is_last():
        msg = states.take()
        if msg is not None:
            seen.append(msg.seq)
        if not seen or seen[-1] != 50:  # the states' QoS drops under congestion: the newest again, if it was lost
            sim.publish(sim.keys.robot_state, state(50))
        return seen and seen[-1] == 50

    wait_for(newest_is_last)
    assert seen == sorted(seen) and len(seen) < 50  # older samples were overwritten, never queued
    assert states.take() is None


def test_a_deeper_reader_holds_the_newest_samples_in_order_and_counts_the_bad_ones(peers):
    """``depth`` N: Zenoh holds the newest N (no Python per sample); ``take_all`` gives them oldest first, each
    once, and counts a bad one. The states' publisher drops under congestion (the control path's QoS), so the
    test sends on until what it waits for has come, and asks for order, not for every sample."""
    sim, ctrl = peers
    states = ctrl.latest(ctrl.keys.robot_state, RobotState, depth=64)
    wait_subscribed(sim.session, sim.keys.robot_state)
    got: list[int] = []
    sent = [0]

    def send(garbage: bool = False) -> None:
        if garbage:
            sim.session.put(sim.keys.robot_state, b"garbage")
        sent[0] += 1
        sim.publish(sim.keys.robot_state, state(sent[0]))

    for _ in range(40):
        send()

    def caught_up(garbage: bool = False) -> bool:
        got.extend(m.seq for m in states.take_all())
        if got and got[-1] == sent[0] and len(got) >= 20 and (not garbage or sum(states.bad.values()) >= 1):
            return True
        send(garbage)  # the last one may have been dropped: another
        return False

    wait_for(lambda: caught_up(), 10.0, "the newest state", period_s=0.02)
    assert len(got) >= 20 and got == sorted(set(got)), got  # in order, each once
    wait_for(lambda: caught_up(garbage=True), 10.0, "a bad sample counted", period_s=0.02)
    assert got == sorted(set(got)) and states.take_all() == []


@pytest.mark.attack('payloads', 'garbage, NaN and wrong-length samples on a key',
                    'counted and dropped, the reader goes on')
def test_bad_samples_are_counted_and_dropped_and_the_reader_goes_on(peers):
    sim, ctrl = peers
    states = ctrl.latest(ctrl.keys.robot_state, RobotState)
    wait_subscribed(sim.session, sim.keys.robot_state)
    raw = sim.session.declare_publisher(sim.keys.robot_state)
    bad_payloads = [b"garbage", encode(state(1))[:-3], encode(Estop(stamp_ns=1, engaged=True, reason="x"))]
    decoded = []
    for n, payload in enumerate(bad_payloads, 1):
        raw.put(payload)

        def taken(n=n):  # one at a time: the reader keeps only the newest payload
            msg = states.take()
            if msg is not None:
                decoded.append(msg)
            return states.received >= n

        wait_for(taken, what=f"the reader taking bad payload {n}")
    assert decoded == []
    assert sum(states.bad.values()) == 3 and states.received == 3
    assert any("expected a RobotState, got a Estop" in reason for reason in states.bad)
    sim.publish(sim.keys.robot_state, state(2))
    assert wait_for(states.take).seq == 2
    raw.undeclare()


@pytest.mark.attack('payloads', "samples far over their type's size bound",
                    'dropped before decoding, counted')
def test_an_oversized_sample_is_dropped_before_it_is_parsed(peers):
    """A well-formed RobotState 10x larger than any robot's is counted and dropped; the next good one decodes."""
    sim, ctrl = peers
    states = ctrl.latest(ctrl.keys.robot_state, RobotState)
    inbox = ctrl.inbox(ctrl.keys.robot_state, RobotState)
    wait_subscribed(sim.session, sim.keys.robot_state)
    n = 20_000  # joints: about 0.5 MB, well-formed, and would cost a 1 kHz loop milliseconds to decode
    huge = RobotState(seq=1, stamp_ns=1, q_rad=[0.1] * n, dq_rad_s=[0.0] * n, tau_nm=[0.0] * n,
                      wrench_world=[0.0] * 6, capabilities=Capabilities(False, [1.0] * n))
    payload = encode(huge)
    assert len(payload) > 10 * 16_384
    sim.session.put(sim.keys.robot_state, payload)
    wait_for(lambda: states.take() is None and states.received >= 1, what="the newest-sample reader taking it")
    wait_for(lambda: inbox.received >= 1, what="the in-order reader taking it")
    for reader in (states, inbox):
        assert list(reader.bad) == ["oversized RobotState payload"], reader.bad
    assert inbox.get(0.0) is None
    sim.publish(sim.keys.robot_state, state(2))
    assert wait_for(states.take).seq == 2 and inbox.get(5.0).seq == 2


def test_liveliness_follows_the_service():
    port = free_port()
    robot = f"t{port}"
    watcher = ServiceNode("tests", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=robot))
    with watcher:
        with ServiceNode("perception", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=robot)):
            wait_alive(watcher, "perception")
        wait_gone(watcher, "perception")


def test_a_restarted_service_is_heard_again_within_a_second_of_listening():
    """A peer that connects to a service (the recorder to the controller) retries the lost link every second at
    most (:data:`runtime.session.CONNECT_RETRY`): down 3.2 s, Zenoh's own back-off (1, 2, 4 s) would next try
    3.8 s after the service listens again; ours tries within 1 s of it. A CI run's recorder missed a restarted
    controller for its last 7 s."""
    port = free_port()
    robot = f"t{port}"
    listen = ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=robot)
    with ServiceNode("recorder", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=robot)) as watcher:
        with ServiceNode("controller", listen):
            wait_alive(watcher, "controller")
        wait_gone(watcher, "controller")
        time.sleep(3.2)
        with ServiceNode("controller", listen):
            t0 = time.monotonic()
            wait_alive(watcher, "controller")
            assert time.monotonic() - t0 < 2.5


def test_the_reconnect_back_off_is_ours_unless_a_zenoh_file_sets_one(tmp_path):
    import json

    from runtime.session import CONNECT_RETRY, CONNECT_RETRY_PATH, zenoh_config

    assert json.loads(zenoh_config(ZenohSettings()).get_json(CONNECT_RETRY_PATH)) == CONNECT_RETRY
    own = _zenoh_file(tmp_path / "zenoh.json5", "{ connect: { retry: { period_init_ms: 3000, period_max_ms: 9000,"
                                                 " period_increase_factor: 3 } } }")
    got = json.loads(zenoh_config(ZenohSettings(config_file=own)).get_json(CONNECT_RETRY_PATH))
    assert (got["period_init_ms"], got["period_max_ms"]) == (3000, 9000)


def test_other_prefixes_are_not_heard():
    port = free_port()
    a = ServiceNode("sim", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id="cell-a"))
    b = ServiceNode("controller", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id="cell-b"))
    with a, b:
        states = b.latest(b.keys.robot_state, RobotState)
        marks = b.inbox(b.keys.controller_estop, Estop)
        wait_subscribed(a.session, b.keys.robot_state)  # b's subscriptions are known to a
        wait_subscribed(a.session, b.keys.controller_estop)
        a.publish(a.keys.robot_state, state(1))
        # a mark on b's own prefix, sent after it over the same link: once b has the mark, a sample on the
        # other prefix would have arrived before it
        a.publish(b.keys.controller_estop, Estop(stamp_ns=1, engaged=False, reason="mark"))
        assert wait_sample(marks, what="the mark on b's prefix").reason == "mark"
        assert states.take() is None and states.received == 0


def _zenoh_file(path, text: str) -> str:
    path.write_text(text)
    return str(path)


def test_a_zenoh_config_file_adds_what_the_settings_do_not_cover(tmp_path):
    """Zenoh's own downsampling interceptor from the file: states on one key are thinned, other keys not."""
    port = free_port()
    robot = f"t{port}"
    thin = _zenoh_file(tmp_path / "zenoh.json5", f"""{{
      // at most 100 robot states per second leave this peer; everything else untouched
      downsampling: [{{ messages: ["put"], flows: ["egress"],
                        rules: [{{ key_expr: "lamps/{robot}/robot/state", freq: 100.0 }}] }}],
    }}""")
    a = ServiceNode("sim", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=robot, config_file=thin))
    b = ServiceNode("controller", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=robot))
    with a, b:
        wait_alive(b, "sim")
        states = b.inbox(b.keys.robot_state, RobotState, maxlen=1000)
        commands = b.inbox(b.keys.robot_command, TorqueCommand, maxlen=1000)
        wait_subscribed(a.session, a.keys.robot_state)
        wait_subscribed(a.session, a.keys.robot_command)
        t0 = time.monotonic()
        for seq in range(300):
            a.publish(a.keys.robot_state, state(seq))
            a.publish(a.keys.robot_command, TorqueCommand(seq=seq, stamp_ns=1, tau_nm=[0.0] * 7))
            time.sleep(0.001)
        elapsed = time.monotonic() - t0
        # until nothing more arrives for 0.2 s: a put's default congestion control drops under load, so count
        # what arrived rather than wait for all that was sent
        seen: list[int] = []
        wait_for(lambda: seen.append(commands.received) or (len(seen) > 20 and seen[-1] == seen[-21]), 10.0,
                 "the commands to stop arriving", period_s=0.01)
        n_states, n_commands = states.received, commands.received
    assert 1 <= n_states <= 100 * elapsed + 2, (n_states, elapsed)  # at most one per 10 ms passed
    assert n_commands >= 0.8 * 300 and n_commands > 2.5 * n_states, (n_commands, n_states)  # the others untouched


@pytest.mark.parametrize("text, match", [
    ('{ listen: { endpoints: ["tcp/127.0.0.1:7447"] } }', r"listen/endpoints \(set it with \[zenoh\] listen\)"),
    ('{ mode: "router" }', r"sets what the \[zenoh\] settings own: mode"),
    ('{ access_control: { enabled: false, default_permission: "allow" } }', "access_control"),
    ('{ transport: { auth: { usrpwd: { user: "c", password: "p", dictionary_file: "d" } } } }',
     "transport/auth/usrpwd"),
    ('{ transport: { link: { tls: { root_ca_certificate: "ca.pem" } } } }', "transport/link/tls"),
    ("{ listen: ", r"is not a Zenoh configuration: --> 1:11 .* expected array"),
    ("{ no_such_field: 1 }", "is not a Zenoh configuration: .*unknown field `no_such_field`"),
    ('{ transport: { auth: { usrpwd: { user: "controller" } } } }', "Zenoh refused a value in it"),
])
def test_a_zenoh_config_file_is_refused_naming_what_is_wrong(tmp_path, text, match):
    from interfaces.errors import ConfigError
    from runtime.session import zenoh_config

    path = _zenoh_file(tmp_path / "zenoh.json5", text)
    with pytest.raises(ConfigError, match=match):
        zenoh_config(ZenohSettings(config_file=path))
    with pytest.raises(ConfigError, match="is not a file"):
        zenoh_config(ZenohSettings(config_file=str(tmp_path / "missing.json5")))


def test_every_service_takes_a_zenoh_config_file_on_its_command_line(tmp_path):
    import subprocess
    import sys

    from .zenoh_helpers import REPO

    missing = tmp_path / "missing.json5"
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "robot", "--backend", "mock", "--zenoh-config",
                        str(missing)], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and f"config_file '{missing}' is not a file" in r.stderr, r.stderr


def test_the_control_path_is_sent_express_at_real_time_priority_and_camera_frames_last(peers):
    """What a subscriber on the other end sees of each sample's QoS: robot states and commands express at
    REAL_TIME, the e-stop REAL_TIME too, camera frames DATA_LOW, the rest Zenoh's default."""
    import zenoh

    sim, ctrl = peers
    k = sim.keys
    seen: dict[str, tuple] = {}
    sub = ctrl.session.declare_subscriber(f"{k.prefix}/**", lambda s: seen.setdefault(str(s.key_expr),
                                                                                    (s.priority, s.express)))
    try:
        wait_subscribed(sim.session, k.robot_state)
        sim.publish(k.robot_state, state(1))
        sim.publish(k.robot_command, TorqueCommand(seq=1, stamp_ns=1, tau_nm=[0.0] * 7))
        sim.publish(k.controller_estop, Estop(stamp_ns=1, engaged=True, reason="qos", source="test"))
        sim.publish(k.sim_status, ServiceStatus(service="sim", seq=1, stamp_ns=1))
        wait_for(lambda: len(seen) >= 4, what="four samples")
    finally:
        sub.undeclare()
    assert seen[k.robot_state] == seen[k.robot_command] == (zenoh.Priority.REAL_TIME, True)
    assert seen[k.controller_estop] == (zenoh.Priority.REAL_TIME, True)
    assert seen[k.sim_status] == (zenoh.Priority.DATA, False)
    assert publisher_qos(k, k.camera_frame("board")) == {"priority": zenoh.Priority.DATA_LOW}
    assert publisher_qos(k, k.camera_frame("board") + "/info") == {}
