"""The real-time controller's planner thread: re-plans off the 1 kHz path (see :mod:`lampskit.core.chain`).

Python runs one thread at a time; a thread that wants the interpreter
waits until the running one lets go, which a busy thread does every
*switch interval* (5 ms by default: five periods). While a plan runs,
:class:`PlannerThread` lowers the interval to :data:`SWITCH_INTERVAL_S`,
so a waking tick waits that long at most, and gives the default back when
the plan is done (a short interval all the time costs the loop's Zenoh
threads more hand-overs).

A thread that holds the interpreter lets go only while it runs. Under the
fair scheduler, on 2 cores busy with the loops' SCHED_FIFO threads and with
ordinary processes (perception, the recorder), the planner thread holding
the interpreter waited for a core for tens of ms while the loop's thread
waited for the interpreter: the tick stalled 26-106 ms right after a
re-plan in a real-time cell through ``lamps router`` (a priority inversion).
So while the loop that made it runs ``SCHED_FIFO``, each job runs at
``SCHED_FIFO`` :data:`PLAN_PRIORITY`, the lowest real-time priority: above
every ordinary process, below every thread of the loops.
"""

from __future__ import annotations

import os
import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor

from runtime.realtime import keep_fair

#: The interpreter's switch interval while a plan runs [s].
SWITCH_INTERVAL_S = 2e-4
#: SCHED_FIFO priority of a job while the loop runs real-time: the lowest, below the loops' I/O threads.
PLAN_PRIORITY = 1


class PlannerThread(ThreadPoolExecutor):
    """One worker thread, started at construction (create it before the loop's thread turns real-time: a
    thread inherits its creator's scheduling) and kept under the fair scheduler when the loop raises the
    process's I/O threads (:func:`~runtime.realtime.keep_fair`). ``submit`` as for any executor."""

    def __init__(self) -> None:
        super().__init__(max_workers=1, thread_name_prefix="lamps-planner")
        super().submit(keep_fair).result()  # the thread exists from now on, and stays under the fair scheduler
        self._loop_tid = threading.get_native_id()  # the loop's thread, which makes the planner
        self.policy = "fair"  # the planner thread's scheduling in its last job: "fair" or "FIFO <priority>"
        self._normal_s = sys.getswitchinterval()
        self._running = 0
        self._lock = threading.Lock()

    def submit(self, fn, /, *args, **kwargs) -> Future:
        with self._lock:
            self._running += 1
            sys.setswitchinterval(SWITCH_INTERVAL_S)
        future = super().submit(self._run, fn, args, kwargs)
        future.add_done_callback(self._finished)
        return future

    def _run(self, fn, args: tuple, kwargs: dict):
        self._follow_loop()
        return fn(*args, **kwargs)

    def _follow_loop(self) -> None:
        """On the planner thread, before a job: SCHED_FIFO :data:`PLAN_PRIORITY` while the loop's thread runs
        SCHED_FIFO, the fair scheduler otherwise (a loop not real-time, or gone)."""
        try:
            fifo = os.sched_getscheduler(self._loop_tid) == os.SCHED_FIFO
        except OSError:
            fifo = False
        want = f"FIFO {PLAN_PRIORITY}" if fifo else "fair"
        if want == self.policy:
            return
        try:
            if fifo:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PLAN_PRIORITY))
            else:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            self.policy = want
        except OSError:
            pass  # not permitted: the job runs as the thread is

    def _finished(self, _future: Future) -> None:
        with self._lock:
            self._running -= 1
            if self._running == 0:
                sys.setswitchinterval(self._normal_s)

    @property
    def switch_interval_s(self) -> float:
        """The interpreter's switch interval now [s]."""
        return sys.getswitchinterval()
