"""When the controller's status goes out and what its trace sent (:class:`~controller.service.ControllerService`)."""

from __future__ import annotations

import time

from interfaces.messages import ControllerTrace

from .core import TRACE_COLUMNS
from .trace import Trace


class StatusOut:
    """The status's schedule and sequence, and the trace rows sent.

    Parameters
    ----------
    period_s : float
        Between status publications (wall clock) [s].

    Attributes
    ----------
    next_s : float
        When the next status is due (``time.monotonic``) [s].
    seq : int
        Statuses made so far (the last one's ``seq``).
    trace_sent : int
        The trace's rows sent so far (the next to send: its tick number).
    trace_seq : int
        Trace messages sent so far (the last one's ``seq``).
    """

    __slots__ = ("period_s", "next_s", "seq", "trace_sent", "trace_seq")

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.next_s = 0.0
        self.seq = 0
        self.trace_sent = 0
        self.trace_seq = 0

    def due(self, now_s: float, force: bool) -> bool:
        """Whether a status goes out at ``now_s`` [s] (``force``: whenever); if so the next is timed from it."""
        if not force and now_s < self.next_s:
            return False
        self.next_s = now_s + self.period_s
        return True

    def trace_message(self, trace: Trace) -> ControllerTrace | None:
        """The trace's rows not yet sent, as one message (None when there are none); counted as sent."""
        first, rows, dropped = trace.since(self.trace_sent)
        if not len(rows):
            return None
        self.trace_sent = first + len(rows)
        self.trace_seq += 1
        return ControllerTrace(seq=self.trace_seq, stamp_ns=time.monotonic_ns(), columns=list(TRACE_COLUMNS),
                               first_tick=first, n_rows=len(rows), data=rows.astype("<f8").tobytes(),
                               dropped=dropped)
