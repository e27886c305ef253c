"""The message contract: exact round trips, one exception for every bad payload, keys, config."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from interfaces.codec import Decoder, decode, encode
from interfaces.errors import ConfigError, MessageDecodeError
from interfaces.keys import Keys
from interfaces.messages import (
    MAX_PAYLOAD_BYTES,
    MESSAGE_TYPES,
    PHASES,
    SCHEMA_VERSION,
    ArmRequest,
    CameraFrame,
    CameraIntrinsics,
    Capabilities,
    ControllerStatus,
    ControllerTrace,
    Estop,
    Introduction,
    LoopTiming,
    Phase,
    Pose,
    RobotState,
    ServiceStatus,
    SimTruth,
    StainObservation,
    Stains,
    TorqueCommand,
)
from runtime.config import ZenohSettings, load_config

RNG = np.random.default_rng(0)
IDENTITY = Pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])


def _floats(n):
    """Awkward doubles: tiny, huge, negative zero, not representable in float32."""
    v = RNG.normal(size=n) * 10.0 ** RNG.integers(-300, 300, n)
    v[0] = -0.0
    return v.tolist()


def samples():
    cam_int = CameraIntrinsics(615.0, 615.0, 319.5, 239.5, 4, 2)
    return [
        RobotState(seq=7, stamp_ns=123, q_rad=_floats(7), dq_rad_s=_floats(7), tau_nm=_floats(7),
                   wrench_world=_floats(6),
                   capabilities=Capabilities(True, [320.0, 320, 176, 176, 110, 40, 40], "real"),
                   wall_ns=1_700_000_000_000_000_000),
        TorqueCommand(seq=7, stamp_ns=124, tau_nm=_floats(7), mode="torque"),
        CameraFrame(seq=1, stamp_ns=2, camera="board", encoding="rgb8", data=bytes(range(24)), intrinsics=cam_int,
                    T_camera_to_world=Pose([1.0, 0.2, 0.9], [0.5, 0.5, -0.5, 0.5])),
        Stains(seq=3, stamp_ns=4, T_board_to_world=IDENTITY, board_size_m=[1.2, 0.9],
               stains=[StainObservation(2, [0.3, 0.4], [0.8, 0.1, 0.9], 0.07, [0.07, 0.05], 0.4, 0.9, False),
                       StainObservation(5, [0.9, 0.2], [0.8, -0.5, 0.7], 0.05, [0.05, 0.05], 0.0, 1.0, True)],
               camera_world_m=[-0.1, -0.6, 1.0]),
        ControllerStatus(seq=9, stamp_ns=10, phase="WIPE", current_mp="periodic 1", stain_id=2, normal_force_n=9.8,
                         timing=LoopTiming(1000.0, 1012.5, 1100.0, 3.0, 40.0, 5.0, 10000, 2),
                         counters={"bad_state": 1}),
        ControllerTrace(seq=3, stamp_ns=4, columns=["t_s", "phase"], first_tick=100, n_rows=2,
                        data=np.array(_floats(4), "<f8").tobytes()),
        ServiceStatus(service="perception", seq=1, stamp_ns=2, counters={"frames": 10, "dropped": 1}, detail="ok"),
        Estop(stamp_ns=11, engaged=True, reason="operator", source="pendant"),
        SimTruth(seq=4, stamp_ns=5, stain_ids=[0, 1], remaining=[0.25, 1.0], total_dirt=1234.5, contact_force_n=10.1),
        ArmRequest(stamp_ns=12, armed=True, reason="T1 first run", source="operator"),
        Introduction(stamp_ns=13, role="robot", certificate=b"-----BEGIN CERTIFICATE-----", nonce=b"n" * 16),
        TorqueCommand(seq=14, stamp_ns=15, tau_nm=[0.5] * 7, session="s", mac=b"m" * 16),
        Estop(stamp_ns=16, engaged=False, reason="ok", source="operator", wall_ns=17, certificate=b"c",
              signature=b"s" * 70),
    ]


def test_every_message_type_has_a_sample():
    assert {type(m) for m in samples()} == set(MESSAGE_TYPES)


@pytest.mark.parametrize("msg", samples(), ids=lambda m: type(m).__name__)
def test_round_trip_is_exact(msg):
    back = decode(encode(msg), type(msg))
    assert back == msg
    for name in msg.__struct_fields__:
        a, b = getattr(msg, name), getattr(back, name)
        if isinstance(a, list) and a and isinstance(a[0], float):
            assert [math.copysign(1, x) for x in a] == [math.copysign(1, x) for x in b]  # -0.0 kept
            assert np.array_equal(np.array(a).view(np.int64), np.array(b).view(np.int64))  # bit-exact


@pytest.mark.parametrize("msg", samples(), ids=lambda m: type(m).__name__)
def test_wire_layout_is_tag_first_version_last(msg):
    raw = msgspec.msgpack.decode(encode(msg))
    assert raw[0] == type(msg).__name__ and raw[-1] == SCHEMA_VERSION


@pytest.mark.parametrize("msg", samples(), ids=lambda m: type(m).__name__)
def test_garbage_and_truncated_payloads_raise_the_one_exception(msg):
    data = encode(msg)
    dec = Decoder(type(msg))
    nested = b"\x91" * 200_000  # absurdly nested arrays: must not escape as RecursionError
    for bad in (b"", b"\xc1", b"garbage!", bytes(RNG.integers(0, 256, 64, dtype=np.uint8)), data[: len(data) // 2],
                data[:-1], nested, data[:1] + nested):
        with pytest.raises(MessageDecodeError):
            dec(bad)


@pytest.mark.parametrize("msg", samples(), ids=lambda m: type(m).__name__)
def test_wrong_version_is_rejected_and_named(msg):
    raw = msgspec.msgpack.decode(encode(msg))
    raw[-1] = SCHEMA_VERSION + 1
    with pytest.raises(MessageDecodeError, match=f"schema version {SCHEMA_VERSION + 1}, this build reads"):
        decode(msgspec.msgpack.encode(raw), type(msg))


def test_another_message_type_is_rejected_and_named():
    cmd = encode(TorqueCommand(seq=1, stamp_ns=1, tau_nm=[0.0] * 7))
    with pytest.raises(MessageDecodeError, match="expected a RobotState, got a TorqueCommand"):
        decode(cmd, RobotState)


def _patched(msg, index, value):
    raw = msgspec.msgpack.decode(encode(msg))
    raw[index] = value
    return msgspec.msgpack.encode(raw)


@pytest.mark.parametrize(
    "index, value, match",
    [
        (3, [0.0, float("nan"), 0.0, 0.0, 0.0, 0.0, 0.0], "tau_nm must be finite"),
        (3, [0.0, float("inf")] + [0.0] * 5, "tau_nm must be finite"),
        (4, "position", "mode must be one of"),
        (3, "seven", "Expected `array`"),
    ],
)
def test_invalid_torque_commands_are_rejected(index, value, match):
    cmd = TorqueCommand(seq=1, stamp_ns=1, tau_nm=[0.0] * 7)
    with pytest.raises(MessageDecodeError, match=match):
        decode(_patched(cmd, index, value), TorqueCommand)


def test_inconsistent_robot_state_is_rejected():
    state = samples()[0]
    with pytest.raises(MessageDecodeError, match="dq_rad_s has 6 entries but q_rad has 7"):
        decode(_patched(state, 4, [0.0] * 6), RobotState)
    with pytest.raises(MessageDecodeError, match="wrench_world must hold 6"):
        decode(_patched(state, 6, [0.0] * 3), RobotState)


def test_constructors_validate_too():
    with pytest.raises(ValueError, match="unit norm"):
        Pose([0, 0, 0], [1.0, 1.0, 0, 0])
    with pytest.raises(ValueError, match="needs 24 bytes"):
        CameraFrame(seq=0, stamp_ns=0, camera="c", encoding="rgb8", data=b"123",
                    intrinsics=CameraIntrinsics(1.0, 1.0, 0.0, 0.0, 4, 2), T_camera_to_world=IDENTITY)
    with pytest.raises(ValueError, match="phase must be one of INIT, WAIT_PEERS, .*, ESTOP, TEACH, got 'DANCING'"):
        ControllerStatus(seq=0, stamp_ns=0, phase="DANCING")
    with pytest.raises(ValueError, match="unique"):
        Stains(seq=0, stamp_ns=0, T_board_to_world=IDENTITY, board_size_m=[1, 1],
               stains=[samples()[3].stains[0]] * 2)
    with pytest.raises(ValueError, match="camera_world_m must hold 3 numbers, got 2"):
        Stains(seq=0, stamp_ns=0, T_board_to_world=IDENTITY, board_size_m=[1, 1], stains=[], camera_world_m=[1, 2])
    with pytest.raises(ValueError, match="camera_world_m must be finite"):
        Stains(seq=0, stamp_ns=0, T_board_to_world=IDENTITY, board_size_m=[1, 1], stains=[],
               camera_world_m=[1.0, math.nan, 0.0])


def test_a_phase_is_its_name_on_the_wire_and_the_status_checks_against_the_one_list():
    assert PHASES == tuple(p.name for p in Phase) and PHASES[:2] == ("INIT", "WAIT_PEERS")
    assert Phase.WIPE == "WIPE" and f"{Phase.WIPE}" == "WIPE" and "WIPE" in {Phase.WIPE}
    st = ControllerStatus(seq=1, stamp_ns=2, phase=Phase.TRANSITION)
    back = decode(encode(st), ControllerStatus)
    assert back.phase == "TRANSITION" and Phase(back.phase) is Phase.TRANSITION
    assert encode(st) == encode(ControllerStatus(seq=1, stamp_ns=2, phase="TRANSITION"))


# -------------------------------------------------------------------------- keys and config


def test_keys_under_the_prefix():
    k = Keys.for_robot("cell2")
    assert k.robot_state == "lamps/cell2/robot/state"
    assert k.camera_frame("board") == "lamps/cell2/camera/board/frame"
    assert k.alive("sim") == "lamps/cell2/alive/sim"
    assert Keys("lab/a").sim_truth == "lab/a/sim/truth"
    for bad in ("lamps/*", "", "a//b", "lamps/x y"):
        with pytest.raises(ConfigError, match="chunks"):
            Keys(bad)


def test_config_file_and_environment_overrides(tmp_path):
    path = tmp_path / "lamps.toml"
    path.write_text('[zenoh]\nrobot_id = "lab"\nlisten = ["tcp/127.0.0.1:7447"]\n[sim]\nrate_hz = 1000\n')
    cfg = load_config(path, env={})
    assert cfg.zenoh.keys.prefix == "lamps/lab" and cfg.zenoh.listen == ("tcp/127.0.0.1:7447",)
    assert cfg.zenoh.mode == "peer" and cfg.zenoh.multicast_scouting is False
    assert cfg.table("sim") == {"rate_hz": 1000} and cfg.table("controller") == {}
    env = {"LAMPS_ZENOH_CONNECT": "tcp/127.0.0.1:1, tcp/127.0.0.1:2", "LAMPS__SIM__RATE_HZ": "500",
           "LAMPS__SIM__MODE": "lock-step", "LAMPS_KEY_PREFIX": "x/y"}
    cfg = load_config(path, env=env)
    assert cfg.zenoh.connect == ("tcp/127.0.0.1:1", "tcp/127.0.0.1:2")
    assert cfg.table("sim") == {"rate_hz": 500, "mode": "lock-step"}
    assert cfg.zenoh.keys.prefix == "x/y"
    assert load_config(None, env={}).zenoh == ZenohSettings()
    # a sub-table, as compose sets the board preset and the stain count
    cfg = load_config(path, env={"LAMPS__SIM__BOARD__PRESET": "table", "LAMPS__SIM__DIRT__STAINS": "2"})
    assert cfg.table("sim") == {"rate_hz": 1000, "board": {"preset": "table"}, "dirt": {"stains": 2}}


@pytest.mark.parametrize(
    "text, env, match",
    [
        ("[zenoh\n", {}, "not valid TOML"),
        ("zenoh = 3\n", {}, "must be a \\[table\\]"),
        ('[zenoh]\nmode = "mesh"\n', {}, "mode must be one of"),
        ('[zenoh]\nlisten = "tcp/1.2.3.4:1"\n', {}, "list of endpoints"),
        ("[zenoh]\nport = 1\n", {}, "unknown key"),
        ("", {"LAMPS_ZENOH_MULTICAST": "maybe"}, "multicast_scouting must be true or false"),
        ("", {"LAMPS__SIM": "1"}, "LAMPS__<SECTION>__<KEY>"),
        ("", {"LAMPS__SIM__RATE_HZ": "5", "LAMPS__SIM__RATE_HZ__X": "1"}, "'rate_hz' is not a table"),
        ("", {"LAMPS_ROBOT_ID": "a b"}, "robot id"),
    ],
)
def test_bad_config_names_the_problem(tmp_path, text, env, match):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_config(path, env=env)


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "nope.toml", env={})


def test_a_payload_larger_than_its_type_may_be_is_refused_unparsed():
    dec = Decoder(TorqueCommand)
    ok = encode(TorqueCommand(seq=1, stamp_ns=2, tau_nm=[0.5] * 7))
    assert dec(ok).seq == 1 and len(ok) < dec.max_bytes
    with pytest.raises(MessageDecodeError, match=r"oversized TorqueCommand payload: 1000000 bytes > 4096, not parsed"):
        dec(b"\x00" * 1_000_000)  # garbage: had it been parsed the error would say "not a msgpack message"
    big = encode(TorqueCommand(seq=1, stamp_ns=2, tau_nm=[0.5] * 1000))
    with pytest.raises(MessageDecodeError, match="oversized TorqueCommand"):
        dec(big)
    for t in MESSAGE_TYPES:  # every type has its bound, and the samples above are all well inside theirs
        assert t in MAX_PAYLOAD_BYTES
    for msg in samples():
        assert len(encode(msg)) < MAX_PAYLOAD_BYTES[type(msg)]


@pytest.mark.parametrize("rate, match", [(-1.0, "state_rate_hz must be >= 0"), (float("nan"), "state_rate_hz")])
def test_a_robot_state_rate_must_be_finite_and_not_negative(rate, match):
    with pytest.raises(ValueError, match=match):
        Capabilities(True, [10.0] * 7, "lbr", rate)
    assert Capabilities(True, [10.0] * 7).state_rate_hz == 0.0, "not declared"


def _wire_with(msg, index: int, value) -> bytes:
    """``msg``'s bytes with field ``index`` of its wire array replaced (bypassing the constructor)."""
    wire = msgspec.msgpack.decode(encode(msg))
    wire[index] = value
    return msgspec.msgpack.encode(wire)


def test_strings_are_bounded_on_the_wire_and_clipped_when_built():
    from interfaces.message_checks import COUNTERS_MAX, DETAIL_MAX, NAME_MAX, TEXT_MAX
    from interfaces.messages import ArmRequest, ServiceStatus

    e = Estop(stamp_ns=1, engaged=True, reason="r" * 10**6, source="s" * 1000)
    assert len(e.reason) == TEXT_MAX and len(e.source) == NAME_MAX, "a producer's long text is clipped"
    assert decode(encode(e), Estop) == e
    ok = Estop(stamp_ns=1, engaged=True, reason="short", source="op")
    wire = msgspec.msgpack.decode(encode(ok))
    i = wire.index("short")
    with pytest.raises(MessageDecodeError):  # a rogue's 1 MB reason never becomes a message
        decode(_wire_with(ok, i, "r" * (TEXT_MAX + 1)), Estop)
    with pytest.raises(MessageDecodeError):
        decode(_wire_with(ok, wire.index("op"), "s" * (NAME_MAX + 1)), Estop)
    assert len(ArmRequest(stamp_ns=1, armed=True, reason="a" * 5000).reason) == TEXT_MAX
    many = {f"reason {i}: " + "x" * 500: 1 for i in range(1000)}
    st = ServiceStatus(service="svc", seq=1, stamp_ns=1, counters=many, detail="d" * 10**5)
    assert len(st.detail) == DETAIL_MAX and len(st.counters) == COUNTERS_MAX
    assert sum(st.counters.values()) == 1000 and "other counters" in st.counters
    assert decode(encode(st), ServiceStatus) == st


@pytest.mark.parametrize("m", [1, 2, 3, 100, 101, 1999, 2000])
def test_the_loops_99th_percentile_is_numpys_bit_for_bit(m):
    from runtime.loop_stats import p99_by_row

    rng = np.random.default_rng(m)
    for b in (rng.exponential(100.0, (4, m)), np.round(rng.normal(50.0, 20.0, (4, m))), np.full((4, m), 7.25)):
        assert np.array_equal(p99_by_row(b), np.percentile(b, 99, axis=1))
