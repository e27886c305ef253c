"""Loop hygiene for a 1 kHz loop: the garbage collector kept out of the period, deadlines slept finely.

:class:`LoopHygiene` is used by every real-time loop (the controller's and
the robot side's, :mod:`robot.server`):

* **Garbage collector.** At :meth:`LoopHygiene.start` everything built so far
  is collected once and frozen (``gc.freeze``: never scanned again) and the
  automatic collector is switched off; the loop then runs the collections
  the interpreter would have run (generation 0 after ``threshold0`` new
  objects, older generations by their thresholds) itself, in the slack
  before a deadline when at least :data:`GC_SLACK_NS` are left, or anyway
  once :data:`GC_FORCE_FACTOR` times the threshold has piled up (memory stays
  bounded). Counted: ``gc_in_slack``, ``gc_forced``.
* **Sleeping.** Linux wakes a sleeping thread up to its *timer slack* late
  (50 us by default); :meth:`start` sets the calling thread's slack to
  :data:`TIMER_SLACK_NS` (``prctl(PR_SET_TIMERSLACK)``), so a sleep to the
  deadline ends within a few microseconds of it, and the last ``spin_ns``
  before the deadline are spun (0 by default: a spinning thread takes the
  CPU the other services of a 2-core cell need). Refused (not Linux): said in
  :attr:`LoopHygiene.report`.
* **Real-time scheduling** (a wall- or robot-clocked loop in a real-time
  service's process, not lock-step): ``SCHED_FIFO`` for the loop's thread,
  locked memory, CPU affinity if asked (:mod:`runtime.realtime`); counted
  as ``loop_sched_fifo_priority`` (0: refused or off) and
  ``loop_memory_locked`` in the service's status counters.

:attr:`LoopHygiene.report` says what was applied, for the service's status, with
the process's CPU priority (:mod:`runtime.priority`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import sys
import time
from collections import Counter

from interfaces.errors import ConfigError

from . import priority
from .realtime import apply_realtime

log = logging.getLogger(__name__)

#: A collection runs in the slack before a deadline only when at least this much of the period is left [ns].
GC_SLACK_NS = 300_000
#: ... or anyway once this many times the generation-0 threshold of new objects has piled up.
GC_FORCE_FACTOR = 20
#: The timer slack asked for the loop's thread [ns].
TIMER_SLACK_NS = 1_000
_PR_SET_TIMERSLACK = 29


def _set_timer_slack(ns: int) -> str:
    if not sys.platform.startswith("linux"):
        return f"timer slack: not on Linux ({sys.platform})"
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        if libc.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) != 0:
            return f"timer slack: refused (errno {ctypes.get_errno()})"
    except (OSError, AttributeError) as exc:
        return f"timer slack: unavailable ({exc})"
    return f"timer slack {ns} ns"


class LoopHygiene:
    """The garbage collector and the sleeps of one real-time loop (module docstring).

    spin_ns : the last part of each wait spent spinning instead of sleeping [ns] (0: none);
    counts : where ``gc_in_slack`` / ``gc_forced`` are counted (the service's status counters; default its own).
    """

    def __init__(self, spin_ns: int = 0, counts: Counter | None = None) -> None:
        self.spin_ns = int(spin_ns)
        self.counts: Counter[str] = Counter() if counts is None else counts
        self.report = "not started"
        self._thresholds = gc.get_threshold()
        self._was_enabled = gc.isenabled()
        self._started = False

    def start(self, realtime: bool = False) -> None:
        """Collect and freeze what exists, take the collector over, fine sleeps for the calling thread; with
        ``realtime`` (a loop on a wall or robot clock, not lock-step) in a process set up as a real-time
        service (:func:`~runtime.priority.set_service_priority`), also real-time scheduling, locked memory
        and the CPUs asked for (:func:`~runtime.realtime.apply_realtime`); a test running a loop in its own
        process is left alone."""
        gc.collect()
        gc.freeze()
        gc.disable()
        self._started = True
        rt = ""
        if realtime and priority.KIND == priority.REALTIME:  # a service's process, not a test running a loop
            try:
                result = apply_realtime()
                rt = "; " + result.report
                for name, value in result.counters().items():
                    self.counts[name] = value
            except ConfigError as exc:  # the service's CLI checks these first; an in-process loop says it here
                rt = f"; real-time scheduling not applied: {exc}"
                log.warning("loop hygiene: %s", exc)
        spin = f"; spin {self.spin_ns // 1000} us" if self.spin_ns else ""
        nice = f"; {priority.REPORT}" if priority.REPORT else ""
        self.report = (f"gc in slack (frozen {gc.get_freeze_count()} objects); {_set_timer_slack(TIMER_SLACK_NS)}"
                       f"{rt}{spin}{nice}")
        log.info("loop hygiene: %s", self.report)

    def stop(self) -> None:
        """Give the collector back (the loop is over)."""
        if self._started:
            gc.unfreeze()
            if self._was_enabled:
                gc.enable()
            self._started = False

    def collect_due(self, left_ns: int) -> None:
        """Run the collection the interpreter would have run by now, if ``left_ns`` of slack allow it (or the
        pile forces it)."""
        t0, t1, t2 = self._thresholds
        count0, count1, count2 = gc.get_count()
        if count0 < t0:
            return
        if left_ns < GC_SLACK_NS and count0 < GC_FORCE_FACTOR * t0:
            return
        generation = 2 if count2 >= t2 else 1 if count1 >= t1 else 0
        gc.collect(generation)
        self.counts["gc_in_slack" if left_ns >= GC_SLACK_NS else "gc_forced"] += 1

    def next_period(self, stats, deadline_ns: int, period_ns: int) -> int:
        """End one period of a fixed-rate loop: the next deadline after ``deadline_ns`` (missed periods counted as
        overruns in ``stats``, a :class:`~runtime.loop_stats.LoopStats`, and skipped), waited for; returns it."""
        deadline_ns = stats.next_deadline(deadline_ns, period_ns, time.monotonic_ns())
        self.wait_until(deadline_ns)
        return deadline_ns

    def wait_until(self, deadline_ns: int) -> None:
        """Spend the rest of the period: due collections if there is slack, then sleep (and spin) to
        ``deadline_ns`` (``time.monotonic_ns`` clock)."""
        if self._started:
            self.collect_due(deadline_ns - time.monotonic_ns())
        left = deadline_ns - time.monotonic_ns()
        if left > self.spin_ns:
            time.sleep((left - self.spin_ns) / 1e9)
        if self.spin_ns:
            while time.monotonic_ns() < deadline_ns:
                pass
