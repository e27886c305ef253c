"""The recorder keeps only what the cell's receivers accept, each key within its own share of the disk budget.

A flood of oversized Stains grew a recording to 2.5 GB, 2.0 GB of it rejected payloads stored as base64; a flood
of perception's debug frames used the whole disk budget and the recording stopped for every key. Now rejected
samples are counted and described (size, error), never stored; a key past its share is thinned (always-recorded
keys) or stopped (images) without touching the others' shares (:mod:`launch.record_budget`); past the whole
budget nothing more is recorded, and the recording says so and still finishes as a whole MCAP file. The pure
rules are checked without Zenoh, the rest over a real Zenoh session pair.
"""

from __future__ import annotations

import math
import secrets
import time

import pytest
import zenoh

from interfaces.access import ROLES, may_put
from interfaces.codec import encode
from interfaces.keys import Keys
from interfaces.messages import MAX_PAYLOAD_BYTES, CameraFrame, RobotState, ServiceStatus
from launch.record import (
    CHUNK_BYTES,
    REJECTED_NOTES_PER_KEY,
    SELF_REPORTS_TOPIC,
    STATUS_TOPIC,
    McapSink,
    Recorder,
    budget_from_env,
    read_recording,
)
from launch.record_budget import FULL, MAX_KEYS, QUEUE_BYTES, SHARES, SHUT, THIN, THIN_FROM, THIN_PERIOD_S, Budget
from launch.record_json import message_type_of
from runtime.config import ZenohSettings
from runtime.session import ServiceNode

from .zenoh_helpers import free_port, wait_for, wait_subscribed

KEYS = Keys.for_robot("bounds")
S = 10**9  # one second [ns]


# ------------------------------------------------------------------------------------------- the rules, pure
def test_the_shares_leave_a_twentieth_for_the_index_and_the_recorders_own_messages():
    assert sum(f for f, _ in SHARES.values()) == pytest.approx(0.95)
    assert [k for k, (_, always) in SHARES.items() if not always] == ["camera/*/frame", "perception/debug"]


def test_every_message_key_of_the_cell_has_an_account_and_a_writer():
    budget = Budget([KEYS], 1024**3)
    keys = [KEYS.robot_state, KEYS.robot_command, KEYS.perception_stains, KEYS.perception_status,
            KEYS.perception_debug, KEYS.controller_status, KEYS.controller_trace, KEYS.controller_estop,
            KEYS.controller_estop_release, KEYS.sim_truth, KEYS.sim_status, KEYS.robot_status, KEYS.robot_arm,
            KEYS.camera_frame("left"), KEYS.camera_frame("right")]
    for key in keys:
        acc = budget.account_of(key)
        assert acc is not None, key
        assert acc.max_bytes == MAX_PAYLOAD_BYTES[message_type_of(KEYS, key)]
        assert any(may_put(KEYS, role, key) for role in ROLES), key
    assert budget.account_of(KEYS.camera_frame("left")) is budget.account_of(KEYS.camera_frame("right"))
    for other in (f"{KEYS.prefix}/perception/other", f"{KEYS.prefix}/camera/a/b/frame", "lamps/elsewhere/robot/state"):
        assert budget.account_of(other) is None, other


def test_an_image_key_stops_at_its_share_and_an_always_recorded_key_is_thinned_first():
    budget = Budget([KEYS], 100 * 1024**2)
    debug, state = budget.account_of(KEYS.perception_debug), budget.account_of(KEYS.robot_state)
    assert debug.share_bytes == int(SHARES["perception/debug"][0] * 100 * 1024**2)
    assert debug.charge(int(THIN_FROM * debug.share_bytes)) is None and debug.state == FULL
    assert debug.charge(debug.share_bytes) == SHUT
    assert budget.admit(debug, 1000, 0) == "over_share"
    assert state.charge(math.ceil(THIN_FROM * state.share_bytes)) == THIN
    t0 = 5 * S
    assert budget.admit(state, 500, t0) is None
    assert budget.admit(state, 500, t0 + S // 2) == "thinned"
    assert budget.admit(state, 500, t0 + int(THIN_PERIOD_S * S)) is None
    assert state.charge(state.share_bytes) == SHUT
    assert state.dropped == {"thinned": 1} and state.received == 3 and debug.dropped == {"over_share": 1}


def test_each_key_has_its_own_part_of_the_queue_at_least_one_message_of_its_largest():
    budget = Budget([KEYS], 1024**3)
    debug, state = budget.account_of(KEYS.perception_debug), budget.account_of(KEYS.robot_state)
    assert debug.queue_bytes == MAX_PAYLOAD_BYTES[CameraFrame]  # its share of the queue is less than one frame
    assert state.queue_bytes == int(QUEUE_BYTES * SHARES["robot/state"][0]) > MAX_PAYLOAD_BYTES[RobotState]
    assert budget.admit(debug, 12_000_000, 0) is None
    assert budget.admit(debug, 12_000_000, 1) == "queue_full"  # a flood of frames waits for none but its own
    assert budget.admit(state, 400, 2) is None
    budget.taken(debug, 12_000_000)
    assert budget.admit(debug, 12_000_000, 3) is None
    assert budget.queue_bound() < 80 * 1024**2, budget.queue_bound()


def test_the_recorder_remembers_at_most_max_keys_cameras_and_no_key_of_another_kind():
    budget = Budget([KEYS], 1024**3)
    for i in range(2 * MAX_KEYS):
        assert budget.account_of(f"{KEYS.prefix}/perception/x{i}") is None
    assert budget.account_of(KEYS.robot_state) is not None
    assert all(budget.account_of(KEYS.camera_frame(f"c{i}")) is not None for i in range(MAX_KEYS - 1))
    assert budget.account_of(KEYS.camera_frame("one-too-many")) is None
    assert len(budget._by_key) == MAX_KEYS


def test_each_message_is_charged_to_its_account_and_the_charges_add_up_to_the_file(tmp_path):
    sink = McapSink(tmp_path / "x.mcap")
    for i in range(3000):
        sink.account = "a" if i % 3 else "b"
        sink.write_json("t/a" if i % 3 else "t/b", "s", {"i": i, "pad": secrets.token_hex(64)}, i, {"type": "object"})
    sink.finish()
    a, b = sink.used("a"), sink.used("b")
    assert a == pytest.approx(2 * b, rel=0.05)
    # compressed chunks shared in proportion, the last at the compression of those before it, the index to nobody
    assert 0.95 < (a + b) / (tmp_path / "x.mcap").stat().st_size < 1.0


def test_the_budget_setting_is_checked(monkeypatch):
    monkeypatch.setenv("LAMPS_RECORD_MAX_MB", "12")
    assert budget_from_env() == 12 * 1024**2
    monkeypatch.setenv("LAMPS_RECORD_MAX_MB", "lots")
    with pytest.raises(ValueError, match="LAMPS_RECORD_MAX_MB must be a positive number of MiB, got 'lots'"):
        budget_from_env()


# ------------------------------------------------------------------------------------------- over real Zenoh
def _pair(rid: str):
    port = free_port()
    a = ServiceNode("recorder", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=rid)).__enter__()
    b = ServiceNode("attacker", ZenohSettings(connect=(f"tcp/127.0.0.1:{port}",), robot_id=rid)).__enter__()
    return a, b


@pytest.mark.attack('7', 'a flood of oversized Stains at the recorder',
                    'counted and described, never stored')
def test_rejected_samples_are_counted_and_described_never_stored(tmp_path):
    rec_node, pub = _pair(f"rb{free_port()}")
    try:
        rec = Recorder(rec_node.session, rec_node.keys, tmp_path)
        key = rec_node.keys.perception_stains
        wait_subscribed(pub.session, key)
        big = b"\x00" * 300_000  # over the Stains size bound (256 KiB): no receiver parses it
        want = REJECTED_NOTES_PER_KEY + 50
        end = time.monotonic() + 60.0
        while rec.counters["undecodable"] < want and time.monotonic() < end:  # a congested put may be dropped
            for _ in range(20):
                pub.session.put(key, big)
            time.sleep(0.05)
        pub.publish(pub.keys.perception_status, ServiceStatus(service="p", seq=1, stamp_ns=1))
        wait_for(lambda: rec.counters["undecodable"] >= want and rec.counters.get("perception/status", 0) >= 1,
                 30.0, "the flood counted")
        received = rec.counters["undecodable"]
        path = rec.close()
    finally:
        pub.close()
        rec_node.close()
    assert path.stat().st_size < 200_000, path.stat().st_size  # 45 MB and more arrived; none of it is stored
    assert received >= REJECTED_NOTES_PER_KEY + 50
    msgs = read_recording(path)
    notes = msgs[key + "/rejected"]
    assert len(notes) == REJECTED_NOTES_PER_KEY and notes[0][1]["bytes"] == len(big)
    assert "over" in notes[0][1]["error"] or "bytes" in notes[0][1]["error"], notes[0][1]
    assert not any(topic.endswith("/raw") for topic in msgs)
    (stains,) = [a for a in msgs[STATUS_TOPIC][-1][1]["keys"] if a["key"] == key]
    assert stains["dropped"]["oversized"] == received and stains["recorded"] == 0


def _status(i: int) -> ServiceStatus:
    """A status that does not compress away (its share is counted in the file's compressed bytes)."""
    return ServiceStatus(service="p", seq=i, stamp_ns=i, detail=secrets.token_hex(400),
                         counters={secrets.token_hex(8): j for j in range(40)})


@pytest.mark.attack('7', 'a recording past its disk budget',
                    'nothing more recorded; recorder/budget says so')
def test_past_its_budget_the_recorder_records_nothing_more_and_says_so(tmp_path):
    """Each key's share leaves 5 % of the budget: the whole is reached by what an earlier recorder of the folder
    left (a recorder restarted in a run folder carries its predecessor's recording over, :mod:`launch.record`)."""
    earlier = McapSink(tmp_path / "recording.mcap.partial")
    for i in range(1500):
        earlier.write(KEYS.perception_status, _status(i), 1_000_000 + i)
    earlier.flush()  # whole chunks on the disk; then its recorder was killed
    carried = earlier.bytes_written()
    assert carried > 400_000 + CHUNK_BYTES  # past the budget even with the last chunk still open
    rec_node, pub = _pair(f"rb{free_port()}")
    try:
        rec = Recorder(rec_node.session, KEYS, tmp_path, budget_bytes=400_000)
        key = KEYS.sim_status  # within its own share: the earlier perception statuses used theirs
        wait_subscribed(pub.session, key)
        for i in range(500):
            pub.publish(key, ServiceStatus(service="p", seq=i, stamp_ns=i))
        wait_for(lambda: rec.counters["dropped_over_budget"] > 0, 10.0, "samples past the budget dropped")
        assert rec.over_budget and rec.counters["sim/status"] == 0
        path = rec.close()
    finally:
        pub.close()
        rec_node.close()
    assert path.stat().st_size < carried + 64 * 1024, (path.stat().st_size, carried)
    msgs = read_recording(path)
    assert "disk budget" in msgs["recorder/budget"][0][1]["message"]
    assert len(msgs[KEYS.perception_status]) == rec.counters["carried_over"]
    # of the new samples only the sim's newest status is there, written at the recorder's close whatever the budget
    (_, copies), = msgs[SELF_REPORTS_TOPIC]
    assert [t for t, _ in msgs[KEYS.sim_status]] == [c["log_time_ns"] for c in copies["messages"]]
    assert 1 <= len(copies["messages"]) <= 2  # the newest of each second: the puts took a second at most


@pytest.mark.slow
def test_a_flood_on_one_key_is_thinned_or_stopped_at_its_share_and_the_others_keep_theirs(tmp_path):
    """Perception's status flooded past its share is thinned to one a second; its debug frames past theirs stop;
    the robot's states, sent all along, are every one recorded."""
    rec_node, pub = _pair(f"rb{free_port()}")
    budget = 40 * 1024**2  # perception/status 420 kB (thinned past 377 kB), perception/debug 2.3 MB
    try:
        rec = Recorder(rec_node.session, rec_node.keys, tmp_path, budget_bytes=budget)
        k = rec_node.keys
        wait_subscribed(pub.session, k.perception_status)
        status = rec.budget.account_of(k.perception_status)
        frame = _frame(640, 480)
        # the states sent blocking: a congested link drops a control-path publisher's states before they leave
        states = pub.session.declare_publisher(k.robot_state, congestion_control=zenoh.CongestionControl.BLOCK)
        i = 0
        while status.state == FULL and i < 2000:
            pub.publish(k.perception_status, _status(i))
            states.put(encode(_state(i)))
            if i % 10 == 0:
                pub.publish(k.perception_debug, frame)
            i += 1
            time.sleep(0.002)
        assert status.state == THIN, status.summary()
        recorded_when_thinned, t_thin = status.recorded, time.monotonic()
        while time.monotonic() - t_thin < 3.0:  # 3 s more of the flood: about three more recorded
            pub.publish(k.perception_status, _status(i))
            states.put(encode(_state(i)))
            pub.publish(k.perception_debug, frame)
            i += 1
            time.sleep(0.002)
        wait_for(lambda: rec.counters["robot/state"] == i, 10.0, "every state recorded")
        thinned = status.recorded - recorded_when_thinned
        path = rec.close()
    finally:
        pub.close()
        rec_node.close()
    assert 2 <= thinned <= 5, thinned
    debug = rec.budget.account_of(rec_node.keys.perception_debug)
    assert debug.state == SHUT and debug.dropped["over_share"] > 0, debug.summary()
    msgs = read_recording(path)
    said = {m["key"]: m["state"] for _, m in msgs["recorder/budget"]}
    assert said == {k.perception_status: THIN, k.perception_debug: SHUT}, said
    assert [m["seq"] for _, m in msgs[k.robot_state]] == list(range(i))


def _frame(w: int, h: int) -> CameraFrame:
    from interfaces.messages import CameraIntrinsics, Pose

    return CameraFrame(seq=0, stamp_ns=0, camera="debug", encoding="rgb8", data=secrets.token_bytes(w * h * 3),
                       intrinsics=CameraIntrinsics(fx=500.0, fy=500.0, cx=w / 2, cy=h / 2, width=w, height=h),
                       T_camera_to_world=Pose([0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0]))


def _state(i: int) -> RobotState:
    from interfaces.messages import Capabilities

    return RobotState(seq=i, stamp_ns=i, q_rad=[0.1] * 7, dq_rad_s=[0.0] * 7, tau_nm=[0.0] * 7,
                      wrench_world=[0.0] * 6, capabilities=Capabilities(True, [100.0] * 7))
