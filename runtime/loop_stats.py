"""What a fixed-rate loop measures about itself: period and its parts in ring buffers, overruns, deadlines.

Shared by every loop of the cell (controller, robot side) so each reports
the same :class:`~interfaces.messages.LoopTiming`.
"""

from __future__ import annotations

import math

import numpy as np

from interfaces.messages import LoopTiming

DEFAULT_WINDOW = 2000


class LoopStats:
    """Ring buffers of the loop period and its read / update / write parts [us], and the overrun count."""

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        self.buf = np.zeros((4, window))
        self.n = 0
        self.overruns = 0

    def add(self, period_us: float, read_us: float, update_us: float, write_us: float) -> None:
        i = self.n % self.buf.shape[1]
        b = self.buf
        b[0, i], b[1, i], b[2, i], b[3, i] = period_us, read_us, update_us, write_us
        self.n += 1

    def next_deadline(self, deadline_ns: int, period_ns: int, now_ns: int) -> int:
        """The deadline after ``deadline_ns``; missed periods are counted as overruns and skipped, never caught up."""
        deadline_ns += period_ns
        if now_ns > deadline_ns:
            missed = (now_ns - deadline_ns) // period_ns + 1
            self.overruns += int(missed)
            deadline_ns += int(missed) * period_ns
        return deadline_ns

    def summary(self) -> LoopTiming:
        m = min(self.n, self.buf.shape[1])
        if m == 0:
            return LoopTiming(overruns=self.overruns)
        b = self.buf[:, :m]
        p99 = p99_by_row(b)  # this runs inside the loop
        return LoopTiming(float(np.median(b[0])), float(p99[0]), float(b[0].max()), float(p99[1]), float(p99[2]),
                          float(p99[3]), self.n, self.overruns)


def p99_by_row(b: np.ndarray) -> np.ndarray:
    """``np.percentile(b, 99, axis=1)`` of ``b`` (k, m), no NaN in it, bit for bit (numpy's linear method: index
    ``(m - 1) 0.99``, the two order statistics around it interpolated as numpy's ``_lerp`` does), from one partition
    of each row: numpy's call partitions the transposed (m, k) view, several times slower."""
    m = b.shape[1]
    virtual = (m - 1) * 0.99
    lo = math.floor(virtual)
    if virtual >= m - 1:
        return b.max(axis=1)
    part = np.partition(b, (lo, lo + 1), axis=1)
    below, above = part[:, lo], part[:, lo + 1]
    gamma = virtual - lo
    diff = above - below
    return above - diff * (1 - gamma) if gamma >= 0.5 else below + diff * gamma
