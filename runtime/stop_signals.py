"""SIGTERM / SIGINT to a service's stop event: a handler that never blocks, and a wait the signal always ends.

Two ways a Python service can miss its stop signal, and what this module does:

* The kernel hands a process's signal to any of its threads, with Zenoh's
  threads running often not the main one. Python runs the handler in the
  main thread, but only once that thread comes back to Python code: a main
  thread blocked in ``Event.wait()`` without a timeout never does (a
  ``lamps router`` at ``--status-s 0`` hung so in CI, 4 stops in 37 on a
  loaded machine here). :func:`wait_for` waits in slices of
  :data:`SIGNAL_POLL_S`.
* The handler runs between two bytecodes of the main thread; when those are
  inside ``stop.wait()`` holding the event's lock, a ``stop.set()`` in the
  handler waits for itself for ever. :func:`on_stop_signals`' handler hands
  the set to a new low-level thread (none of :mod:`threading`'s locks taken).

A background service also leaves its low CPU priority in the handler
(:func:`runtime.priority.leave_background`).
"""

from __future__ import annotations

import _thread
import signal
import threading
import time

from .priority import leave_background

#: Longest a :func:`wait_for` goes without giving a pending signal handler its turn [s].
SIGNAL_POLL_S = 0.2


def on_stop_signals(stop: threading.Event, background: bool = False,
                    signals: tuple[int, ...] = (signal.SIGTERM, signal.SIGINT)) -> None:
    """Set ``stop`` on each of ``signals`` (call from the main thread); ``background``: also leave the background
    priority at once (a stop is due: the service's exit now holds up the others)."""

    def handle(*_) -> None:
        if background:
            leave_background()  # no lock, no logging: safe here
        _thread.start_new_thread(stop.set, ())  # may wait for the event's lock, which this thread may hold

    for sig in signals:
        signal.signal(sig, handle)


def wait_for(stop: threading.Event, timeout_s: float | None = None) -> bool:
    """Wait until ``stop`` is set (True) or ``timeout_s`` [s] has passed (False; None: no limit), in slices of
    :data:`SIGNAL_POLL_S` so a signal handled by another thread still reaches the main one."""
    end = None if timeout_s is None else time.monotonic() + timeout_s
    while True:
        left = SIGNAL_POLL_S if end is None else min(SIGNAL_POLL_S, end - time.monotonic())
        if left <= 0.0:
            return stop.is_set()
        if stop.wait(left):
            return True
