"""The recorder keeps only what the cell's receivers accept and stays within its disk budget.

A flood of oversized Stains grew a recording to 2.5 GB, 2.0 GB of it rejected payloads stored as base64. Over a
real Zenoh session pair: rejected samples are counted and described (size, error), never stored; past the
budget nothing more is recorded, and the recording says so and still finishes as a whole MCAP file.
"""

from __future__ import annotations

import time

import pytest

from interfaces.config import ZenohSettings
from interfaces.messages import ServiceStatus
from interfaces.session import ServiceNode
from launch.record import REJECTED_NOTES_PER_KEY, Recorder, budget_from_env, read_recording

from .zenoh_helpers import free_port, wait_for, wait_subscribed


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


@pytest.mark.attack('7', 'a recording past its disk budget',
                    'nothing more recorded; recorder/budget says so')
def test_past_its_budget_the_recorder_records_nothing_more_and_says_so(tmp_path):
    rec_node, pub = _pair(f"rb{free_port()}")
    try:
        rec = Recorder(rec_node.session, rec_node.keys, tmp_path, budget_bytes=400_000)
        key = rec_node.keys.perception_status
        wait_subscribed(pub.session, key)
        t_end = time.monotonic() + 20.0
        i = 0
        while not rec.over_budget and time.monotonic() < t_end:
            pub.publish(key, ServiceStatus(service="p", seq=i, stamp_ns=i, detail="x" * 2000,
                                           counters={f"c{j}": j for j in range(50)}))
            i += 1
            if i % 200 == 0:
                time.sleep(0.05)
        assert rec.over_budget, "the budget was never reached"
        for _ in range(500):
            pub.publish(key, ServiceStatus(service="p", seq=i, stamp_ns=i))
        wait_for(lambda: rec.counters["dropped_over_budget"] > 0, 10.0, "samples past the budget dropped")
        path = rec.close()
    finally:
        pub.close()
        rec_node.close()
    assert path.stat().st_size < 400_000 + 2 * 256 * 1024, path.stat().st_size
    msgs = read_recording(path)
    assert "disk budget" in msgs["recorder/budget"][0][1]["message"]


def test_the_budget_setting_is_checked(monkeypatch):
    monkeypatch.setenv("LAMPS_RECORD_MAX_MB", "12")
    assert budget_from_env() == 12 * 1024**2
    monkeypatch.setenv("LAMPS_RECORD_MAX_MB", "lots")
    with pytest.raises(ValueError, match="LAMPS_RECORD_MAX_MB must be a positive number of MiB, got 'lots'"):
        budget_from_env()
