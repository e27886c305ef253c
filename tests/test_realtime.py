"""Real-time scheduling for a loop's thread: what the environment asks, what the operating system grants.

Applied in child processes (a loop's process), never in the test runner's own.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import subprocess
import sys

import pytest

from interfaces.errors import ConfigError
from runtime.realtime import DEFAULT_PRIORITY, RealtimeRequest

from .conftest import REPO

CHILD = """
import os, threading
from runtime.realtime import RealtimeRequest, apply_realtime, keep_fair
ids, stop = {{}}, threading.Event()
def worker(name, fair):
    if fair:
        keep_fair()
    ids[name] = threading.get_native_id()
    stop.wait()
threads = [threading.Thread(target=worker, args=(n, n == "planner")) for n in ("io", "planner")]
for t in threads:
    t.start()
while len(ids) < 2:
    pass
result = apply_realtime(RealtimeRequest({priority}, {mlock}, {cpus}, {io}))
policy = os.sched_getscheduler(0)
print(result.report)
print(result.fifo_priority, int(result.memory_locked), int(policy == os.SCHED_FIFO),
      os.sched_getparam(0).sched_priority, ",".join(map(str, sorted(os.sched_getaffinity(0)))),
      result.io_threads_fifo, *(f"{{n}}:{{os.sched_getscheduler(ids[n])}}:{{os.sched_getparam(ids[n]).sched_priority}}"
                                for n in ("io", "planner")))
stop.set()
"""


_PR_CAPBSET_DROP, _CAP_IPC_LOCK, _CAP_SYS_NICE = 24, 14, 23


def _drop_capabilities() -> None:
    """In the child before exec: take CAP_SYS_NICE and CAP_IPC_LOCK out of the bounding set, so that even
    root's program starts without them (a container without ``cap_add: [SYS_NICE]``)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    for cap in (_CAP_SYS_NICE, _CAP_IPC_LOCK):
        if libc.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def _child(priority, mlock, cpus, unprivileged: bool = False, io: bool = True) -> tuple[str, list[str]]:
    code = CHILD.format(priority=priority, mlock=mlock, cpus=cpus, io=io)
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60,
                       preexec_fn=_drop_capabilities if unprivileged else None)
    assert r.returncode == 0, r.stderr
    report, numbers = r.stdout.strip().splitlines()[-2:]
    return report, numbers.split()


def test_the_environment_asks_fifo_10_and_locked_memory_by_default_and_each_can_be_changed():
    assert RealtimeRequest.from_env({}) == RealtimeRequest(DEFAULT_PRIORITY, True, None)
    assert RealtimeRequest.from_env({"LAMPS_RT_PRIORITY": "off", "LAMPS_MLOCK": "off"}) == \
        RealtimeRequest(None, False, None)
    assert RealtimeRequest.from_env({"LAMPS_RT_PRIORITY": "42", "LAMPS_CPUS": "1,0"}) == \
        RealtimeRequest(42, True, frozenset({0, 1}))
    assert RealtimeRequest.from_env({"LAMPS_RT_IO": "off"}) == RealtimeRequest(io_threads=False)


@pytest.mark.parametrize("env, match", [
    ({"LAMPS_RT_PRIORITY": "99"}, "LAMPS_RT_PRIORITY must be an integer from 1 to 98 or 'off', got '99'"),
    ({"LAMPS_RT_PRIORITY": "high"}, "LAMPS_RT_PRIORITY must be .* got 'high'"),
    ({"LAMPS_MLOCK": "yes"}, "LAMPS_MLOCK must be 'on' or 'off', got 'yes'"),
    ({"LAMPS_RT_IO": "1"}, "LAMPS_RT_IO must be 'on' or 'off', got '1'"),
    ({"LAMPS_CPUS": "1;2"}, "LAMPS_CPUS must be CPU numbers separated by commas"),
    ({"LAMPS_CPUS": "-1"}, "LAMPS_CPUS must be CPU numbers"),
])
def test_a_bad_request_names_the_variable(env, match):
    with pytest.raises(ConfigError, match=match):
        RealtimeRequest.from_env(env)


@pytest.mark.skipif(os.geteuid() != 0, reason="granting SCHED_FIFO and mlockall needs root here")
def test_as_root_the_loop_thread_gets_fifo_locked_memory_and_its_cpu():
    report, (fifo, locked, is_fifo, prio, cpus, raised, io, planner) = _child(10, True, "frozenset({0})")
    assert report == "SCHED_FIFO 10; other threads SCHED_FIFO 9: 1, 1 kept fair; memory locked; CPUs 0"
    assert (fifo, locked, is_fifo, prio, cpus) == ("10", "1", "1", "10", "0")
    # the thread that hands the loop its data runs just below it; the planner stays under the fair scheduler
    assert (raised, io, planner) == ("1", f"io:{os.SCHED_FIFO}:9", f"planner:{os.SCHED_OTHER}:0")


@pytest.mark.skipif(os.geteuid() != 0, reason="granting SCHED_FIFO needs root here")
def test_lamps_rt_io_off_leaves_the_other_threads_fair_and_priority_1_raises_them_to_1():
    report, (*_, raised, io, planner) = _child(10, False, "None", io=False)
    assert report == "SCHED_FIFO 10; other threads fair (LAMPS_RT_IO=off); memory not locked (LAMPS_MLOCK=off)"
    assert (raised, io, planner) == ("0", f"io:{os.SCHED_OTHER}:0", f"planner:{os.SCHED_OTHER}:0")
    report, (*_, raised, io, planner) = _child(1, False, "None")
    assert "other threads SCHED_FIFO 1: 1" in report and io == f"io:{os.SCHED_FIFO}:1", report


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="capability bounding sets are Linux's")
def test_without_the_capabilities_the_loop_says_what_was_refused_and_runs_on():
    report, (fifo, locked, is_fifo, prio, cpus, raised, io, _) = _child(10, True, "None", unprivileged=True)
    assert "SCHED_OTHER (asked FIFO 10: refused, needs CAP_SYS_NICE)" in report
    assert "memory not locked (mlockall:" in report and "ulimit -l unlimited" in report
    assert "other threads" not in report  # nothing raised when the loop itself was refused
    assert (fifo, locked, is_fifo, raised, io) == ("0", "0", "0", "0", f"io:{os.SCHED_OTHER}:0")


def test_off_means_nothing_is_asked():
    report, (fifo, locked, is_fifo, prio, cpus, raised, io, _) = _child(None, False, "None")
    assert report == "SCHED_OTHER (LAMPS_RT_PRIORITY=off); memory not locked (LAMPS_MLOCK=off)"
    assert (fifo, locked, is_fifo, raised, io) == ("0", "0", "0", "0", f"io:{os.SCHED_OTHER}:0")
