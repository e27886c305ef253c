"""A recorder that dies leaves a recording the standard reader can use: small chunks on the disk, recovered up to the
cut by :func:`launch.record.recover_recording` (and by ``lamps report`` on its own)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from interfaces.messages import ServiceStatus
from launch.record import CHUNK_BYTES, RESUMED_TOPIC, McapSink, Recorder, read_recording, recover_recording
from runtime.config import ZenohSettings
from runtime.session import ServiceNode

from .zenoh_helpers import REPO, free_port, wait_for


def _messages(path) -> int:
    with open(path, "rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages())


def _status(i: int) -> ServiceStatus:
    return ServiceStatus(service="svc", seq=i, stamp_ns=i, counters={"n": i, "pad": 12345}, detail="x" * 200)


def test_an_unfinished_recording_is_recovered_up_to_its_last_whole_chunk(tmp_path):
    partial = tmp_path / "recording.mcap.partial"
    sink = McapSink(partial)
    n = 30_000  # about 10 MB of JSON: dozens of chunks
    for i in range(n):
        sink.write("lamps/t/svc/status", _status(i), 1_000_000 + i)
    sink.flush()  # what the recorder does every second; then it is killed: no summary, no footer
    size = partial.stat().st_size
    assert size > 2 * CHUNK_BYTES  # compressed chunks of 256 KiB of JSON each: dozens of them
    with pytest.raises(McapError):  # the standard (indexed) reader cannot read an unfinished file
        _messages(partial)
    recovered = recover_recording(partial, tmp_path / "recording.mcap")
    assert _messages(tmp_path / "recording.mcap") == recovered
    assert n - recovered < 2_000, "at most the last, unfinished chunk is lost"
    # cut anywhere (a crash while a chunk was being written): still a readable file with what came before
    data = partial.read_bytes()
    last = 0
    for cut in (100, size // 3, size // 2, size - 7):
        (tmp_path / "cut.partial").write_bytes(data[:cut])
        got = recover_recording(tmp_path / "cut.partial", tmp_path / f"cut{cut}.mcap")
        assert _messages(tmp_path / f"cut{cut}.mcap") == got and got >= last
        last = got
    assert last > 0.9 * recovered


@pytest.mark.slow
def test_lamps_report_recovers_the_recording_of_a_killed_recorder(tmp_path):
    port = free_port()
    rid = f"rec{port}"
    out = tmp_path / "run"
    env = {**os.environ, "LAMPS_ROBOT_ID": rid, "LAMPS_ZENOH_CONNECT": f"tcp/127.0.0.1:{port}"}
    with ServiceNode("svc", ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=rid)) as node:
        rec = subprocess.Popen([sys.executable, "-m", "runtime.cli", "record", "--out", str(out)], env=env,
                               cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            wait_for(lambda: "recorder" in node.alive_services(0.5), 30.0, "the recorder's liveliness token")
            t_end = time.monotonic() + 3.0
            i = 0
            while time.monotonic() < t_end:
                node.publish(node.keys.perception_status, _status(i))
                i += 1
                time.sleep(0.002)
            time.sleep(1.5)  # past the recorder's next flush
        finally:
            rec.send_signal(signal.SIGKILL)
            rec.wait(10)
    assert not (out / "recording.mcap").exists() and (out / "recording.mcap.partial").is_file()
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "report", str(out)], cwd=REPO, capture_output=True,
                       text=True, timeout=120)
    assert "recovered" in r.stdout, r.stdout + r.stderr
    assert _messages(out / "recording.mcap") > 0.5 * i, (i, r.stdout)


@pytest.mark.parametrize("finished", [False, True], ids=["predecessor-died", "predecessor-finished"])
def test_a_recorder_started_again_continues_the_recording_and_loses_nothing(tmp_path, finished):
    port = free_port()
    settings = ZenohSettings(listen=(f"tcp/127.0.0.1:{port}",), robot_id=f"rec{port}")
    key = settings.keys.perception_status
    earlier = tmp_path / ("recording.mcap" if finished else "recording.mcap.partial")
    sink = McapSink(earlier)
    for i in range(3_000):
        sink.write(key, _status(i), 1_000_000 + i)
    sink.flush()
    if finished:
        sink.finish()
    else:  # killed: no summary; what reached the disk is what the new recorder finds
        on_disk = recover_recording(earlier, tmp_path / "what-was-on-disk.mcap")
    with ServiceNode("perception", settings) as node:
        rec = Recorder(node.session, node.keys, tmp_path)
        assert not earlier.exists() or earlier.name.endswith(".partial")  # replaced only by the carried copy
        for i in range(3_000, 3_050):
            node.publish(key, _status(i))
        wait_for(lambda: rec.counters["perception/status"] == 50, 10.0, "the new statuses recorded")
        path = rec.close()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("recording")) == ["recording.mcap"]
    got = read_recording(path)
    seqs = [m["seq"] for _, m in got[key]]
    expected = 3_000 if finished else on_disk
    assert seqs == list(range(expected)) + list(range(3_000, 3_050)), "every earlier message, in order, then the new"
    assert [t for t, _ in got[key][:expected]] == [1_000_000 + i for i in range(expected)], "their own times"
    (_, marker), = got[RESUMED_TOPIC]
    assert marker["carried_messages"] == expected and marker["earlier_finished"] is finished
    assert marker["last_earlier_ns"] == 1_000_000 + expected - 1


@pytest.mark.attack('6', 'the recorder killed under lamps up',
                    'report.json written from the recovered recording')
def test_lamps_up_recovers_the_recording_of_a_dead_recorder_and_writes_the_report(tmp_path, capsys):
    """The recorder killed: lamps up still leaves report.json, from the recording recovered up to the crash."""
    from launch.cli import show_report

    out = tmp_path / "run"
    out.mkdir()
    sink = McapSink(out / "recording.mcap.partial")
    for i in range(3000):  # past one chunk: a whole chunk reaches the disk
        sink.write("lamps/x/perception/status", _status(i), 1_000_000 + i)
    sink.flush()  # what reached the disk before the crash; no footer
    assert not (out / "recording.mcap").exists()
    rc = show_report(out, "the recorder died")
    assert (out / "report.json").is_file() and (out / "recording.mcap").is_file()
    assert "recovered" in capsys.readouterr().out and rc == 1  # nothing was cleaned in this recording
