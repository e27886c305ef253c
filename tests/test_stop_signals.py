"""SIGTERM ends a service's wait wherever the kernel delivers it, and its handler never blocks
(:mod:`runtime.stop_signals`), each case in its own process."""

from __future__ import annotations

import subprocess
import sys

import pytest

from .zenoh_helpers import REPO

# The main thread waits for its stop event; another thread takes the SIGTERM (as one of Zenoh's threads often does:
# the kernel hands a process's signal to any thread). Prints "stopped" once the wait returns.
ELSEWHERE = """
import signal, sys, threading, time
from runtime.stop_signals import on_stop_signals, wait_for
stop = threading.Event()
on_stop_signals(stop)
def other():
    time.sleep(0.3)
    signal.pthread_kill(threading.get_ident(), signal.SIGTERM)  # to this thread, not the main one
threading.Thread(target=other, daemon=True).start()
t0 = time.monotonic()
if sys.argv[1] == "plain":
    stop.wait()
else:
    wait_for(stop)
print("stopped after %.2f s" % (time.monotonic() - t0), flush=True)
"""

# The handler runs while the main thread holds the event's lock, as it does between two bytecodes inside
# stop.wait() (entering it, it holds the lock for a call or two). Prints "stopped" once the event is set.
LOCK_HELD = """
import signal, sys, threading
from runtime.stop_signals import on_stop_signals
stop = threading.Event()
if sys.argv[1] == "plain":
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
else:
    on_stop_signals(stop)
with stop._cond:  # the event's own lock, held by this thread
    signal.raise_signal(signal.SIGTERM)  # the handler runs here, in this thread
print("stopped" if stop.wait(5.0) else "not stopped", flush=True)
"""


def _run(code: str, *args: str, timeout_s: float = 30.0) -> str:
    r = subprocess.run([sys.executable, "-c", code, *args], cwd=REPO, capture_output=True, text=True,
                       timeout=timeout_s)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_a_stop_signal_another_thread_takes_ends_the_main_threads_wait():
    out = _run(ELSEWHERE, "slices")
    assert out.startswith("stopped after") and float(out.split()[2]) < 1.5, out


def test_without_the_slices_the_same_wait_would_never_end():
    """The case :func:`wait_for` exists for: a plain ``Event.wait()`` misses the handler (a `lamps router` hung)."""
    with pytest.raises(subprocess.TimeoutExpired):
        _run(ELSEWHERE, "plain", timeout_s=3.0)


def test_a_stop_signal_handled_while_the_main_thread_holds_the_events_lock_does_not_deadlock():
    assert _run(LOCK_HELD, "handed", timeout_s=30.0).strip() == "stopped"
    with pytest.raises(subprocess.TimeoutExpired):  # a handler that set the event itself waits for itself
        _run(LOCK_HELD, "plain", timeout_s=3.0)
