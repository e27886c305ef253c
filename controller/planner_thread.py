"""The real-time controller's planner thread: re-plans off the 1 kHz path (see :mod:`lampskit.core.chain`).

Python runs one thread at a time; a thread that wants the interpreter
waits until the running one lets go, which a busy thread does every
*switch interval* (5 ms by default: five periods). While a plan runs,
:class:`PlannerThread` lowers the interval to :data:`SWITCH_INTERVAL_S`,
so a waking tick waits that long at most, and gives the default back when
the plan is done (a short interval all the time costs the loop's Zenoh
threads more hand-overs).
"""

from __future__ import annotations

import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor

from runtime.realtime import keep_fair

#: The interpreter's switch interval while a plan runs [s].
SWITCH_INTERVAL_S = 2e-4


class PlannerThread(ThreadPoolExecutor):
    """One worker thread, started at construction (create it before the loop's thread turns real-time: a
    thread inherits its creator's scheduling) and kept under the fair scheduler when the loop raises the
    process's I/O threads (:func:`~runtime.realtime.keep_fair`). ``submit`` as for any executor."""

    def __init__(self) -> None:
        super().__init__(max_workers=1, thread_name_prefix="lamps-planner")
        super().submit(keep_fair).result()  # the thread exists from now on, and stays under the fair scheduler
        self._normal_s = sys.getswitchinterval()
        self._running = 0
        self._lock = threading.Lock()

    def submit(self, fn, /, *args, **kwargs) -> Future:
        with self._lock:
            self._running += 1
            sys.setswitchinterval(SWITCH_INTERVAL_S)
        future = super().submit(fn, *args, **kwargs)
        future.add_done_callback(self._finished)
        return future

    def _finished(self, _future: Future) -> None:
        with self._lock:
            self._running -= 1
            if self._running == 0:
                sys.setswitchinterval(self._normal_s)

    @property
    def switch_interval_s(self) -> float:
        """The interpreter's switch interval now [s]."""
        return sys.getswitchinterval()
