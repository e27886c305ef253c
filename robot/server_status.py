"""The robot server's status (:meth:`~robot.server.RobotServer.status`): where and when it goes, and the answer
latency it reports."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Answer latencies kept for the status's percentiles (the newest).
LATENCY_RING = 2000


@dataclass(slots=True)
class StatusOut:
    """Where the status goes and when next.

    Attributes
    ----------
    service : str
        The name in the status.
    key : str
        The key it is published on.
    period_s : float
        Between publications (wall clock) [s].
    next_s : float
        When the next is due (``time.monotonic``) [s].
    """

    service: str
    key: str
    period_s: float
    next_s: float = 0.0

    def due(self, now_s: float, force: bool) -> bool:
        """Whether a status goes out at ``now_s`` [s] (``force``: whenever); if so the next is timed from it."""
        if not force and now_s < self.next_s:
            return False
        self.next_s = now_s + self.period_s
        return True


@dataclass(slots=True)
class AnswerLatency:
    """A clocked robot's round trip through the controller: state published -> its answer forwarded.

    Attributes
    ----------
    us : ndarray, shape (LATENCY_RING,)
        The latencies [us], a ring (the newest :data:`LATENCY_RING`).
    n : int
        Latencies recorded so far.
    """

    us: np.ndarray = field(default_factory=lambda: np.zeros(LATENCY_RING))
    n: int = 0

    def add(self, latency_us: float) -> None:
        """Record one answer's latency [us]."""
        self.us[self.n % len(self.us)] = latency_us
        self.n += 1

    def into(self, counters: dict[str, int]) -> None:
        """Add ``answer_latency_p50_us`` and ``answer_latency_p99_us`` to the status ``counters`` (none recorded:
        nothing)."""
        if self.n:
            p50, p99 = np.percentile(self.us[:min(self.n, len(self.us))], [50, 99])
            counters.update(answer_latency_p50_us=int(p50), answer_latency_p99_us=int(p99))
