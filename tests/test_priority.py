"""CPU priority per kind of service (:mod:`runtime.priority`), each case in its own process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

from interfaces.errors import ConfigError
from runtime.priority import BACKGROUND, REALTIME, wanted_nice

from .zenoh_helpers import REPO

# In a fresh interpreter: a thread started before the call (as a library's pool would be), the call, a thread
# started after it; prints the report and every thread's nice value.
PROBE = """
import json, os, sys, threading
from runtime.priority import set_service_priority
if os.geteuid() == 0:
    os.setpriority(os.PRIO_PROCESS, 0, 0)  # start from nice 0 whatever the test runner runs at
if len(sys.argv) > 2:
    os.setgid(65534); os.setuid(65534)  # an unprivileged user: no CAP_SYS_NICE
ready, done = threading.Event(), threading.Event()
def idle():
    ready.set(); done.wait()
before = threading.Thread(target=idle, daemon=True); before.start(); ready.wait()
try:
    report = set_service_priority(sys.argv[1])
    after_nice = []
    t = threading.Thread(target=lambda: after_nice.append(os.getpriority(os.PRIO_PROCESS, 0))); t.start(); t.join()
    before_nice = os.getpriority(os.PRIO_PROCESS, before.native_id)
finally:
    done.set()
before.join()
print(json.dumps({"report": report, "main": os.getpriority(os.PRIO_PROCESS, 0), "before": before_nice,
                  "after": after_nice[0]}))
"""


def _probe(kind: str, *extra: str, env: dict | None = None) -> dict:
    r = subprocess.run([sys.executable, "-c", PROBE, kind, *extra], cwd=REPO, capture_output=True, text=True,
                       timeout=60, env={**os.environ, **(env or {})})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_background_services_step_back_every_thread_of_them():
    got = _probe(BACKGROUND)
    assert got == {"report": "nice 10", "main": 10, "before": 10, "after": 10}, got


@pytest.mark.skipif(os.geteuid() != 0, reason="raising a priority needs CAP_SYS_NICE (root here and in CI)")
def test_real_time_services_go_first_when_permitted_and_say_so_when_not():
    assert _probe(REALTIME) == {"report": "nice -10", "main": -10, "before": -10, "after": -10}
    refused = _probe(REALTIME, "as-nobody")
    assert refused["main"] == 0 and refused["report"] == "nice 0 (asked -10: refused, needs CAP_SYS_NICE)", refused


def test_lamps_nice_overrides_or_keeps_and_a_bad_value_is_named():
    assert _probe(BACKGROUND, env={"LAMPS_NICE": "5"})["main"] == 5
    assert _probe(BACKGROUND, env={"LAMPS_NICE": "keep"}) == {"report": "nice 0", "main": 0, "before": 0, "after": 0}
    assert wanted_nice(REALTIME, {}) == -10 and wanted_nice(BACKGROUND, {"LAMPS_NICE": " 19 "}) == 19
    for bad in ("high", "-21", "20", "1.5"):
        with pytest.raises(ConfigError, match="LAMPS_NICE must be an integer from -20 to 19 or 'keep'"):
            wanted_nice(BACKGROUND, {"LAMPS_NICE": bad})
    with pytest.raises(ConfigError, match=r"kind must be one of \['background', 'realtime'\], got 'fast'"):
        wanted_nice("fast", {})


def test_a_bad_lamps_nice_stops_a_service_at_start_up_naming_it(tmp_path):
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "robot", "--backend", "mock"], cwd=REPO,
                       capture_output=True, text=True, timeout=60, env={**os.environ, "LAMPS_NICE": "fast"})
    assert r.returncode == 1 and "LAMPS_NICE must be an integer" in r.stderr, r.stderr


def test_a_check_run_leaves_the_callers_priority_alone():
    from sim import cli

    before = os.getpriority(os.PRIO_PROCESS, 0)
    assert cli.main(["--board", "table", "--check"]) == 0
    assert os.getpriority(os.PRIO_PROCESS, 0) == before


# A background service waiting for its stop: a second thread, the handler of runtime.stop_signals; prints
# "ready", then, once stopped, every thread's nice value.
STOP_PROBE = """
import json, os, signal, sys, threading
from runtime.priority import BACKGROUND, set_service_priority
from runtime.stop_signals import on_stop_signals
if os.geteuid() == 0:
    os.setpriority(os.PRIO_PROCESS, 0, 0)
if len(sys.argv) > 1:
    os.setgid(65534); os.setuid(65534)  # an unprivileged user: no CAP_SYS_NICE
stop, done = threading.Event(), threading.Event()
worker = threading.Thread(target=done.wait, daemon=True); worker.start()
set_service_priority(BACKGROUND)
on_stop_signals(stop, background=True)
print("ready", os.getpriority(os.PRIO_PROCESS, 0), flush=True)
stopped = stop.wait(60)
print(json.dumps({"stopped": stopped, "main": os.getpriority(os.PRIO_PROCESS, 0),
                  "worker": os.getpriority(os.PRIO_PROCESS, worker.native_id)}), flush=True)
done.set()
"""


def _stopped_background(*extra: str, env: dict | None = None) -> dict:
    p = subprocess.Popen([sys.executable, "-c", STOP_PROBE, *extra], cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})})
    try:
        assert p.stdout.readline().split() == ["ready", "10"], p.stderr.read()
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == 0, err
    return json.loads(out)


@pytest.mark.skipif(os.geteuid() != 0, reason="raising a priority needs CAP_SYS_NICE (root here and in CI)")
def test_a_background_service_told_to_stop_leaves_its_low_priority_with_every_thread():
    # another cell's loops at -10 would otherwise leave its exit ~1 % of a core (a perception was killed so)
    assert _stopped_background() == {"stopped": True, "main": 0, "worker": 0}
    # without CAP_SYS_NICE it cannot, and still stops (the loops then run at 0, not -10, either)
    assert _stopped_background("as-nobody") == {"stopped": True, "main": 10, "worker": 10}
    # a nice the user gave (LAMPS_NICE) is theirs: kept
    assert _stopped_background(env={"LAMPS_NICE": "10"}) == {"stopped": True, "main": 10, "worker": 10}
