"""One pure computation at a time off the 1 kHz tick, its answer taken back in a later tick.

Choosing a look point checks the arm's silhouette from some fifty pad
positions against up to two hundred board points: a few control periods
(``bench/bench_look_points.py``). In the real-time loop :attr:`OffTick.executor` is the
planner thread (:mod:`controller.planner_thread`): the tick hands the
computation over and goes on holding the setpoint; a later tick finds the
answer done and acts on it (:meth:`OffTick.poll`). Without an executor
(lock-step, tests) the computation runs at once, in the tick that asks, so a
lock-step run is the same whatever the machine's speed.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor, Future
from typing import Any


class OffTick:
    """One job off the tick at a time.

    Attributes
    ----------
    executor : Executor or None
        Where jobs run (the planner thread), or None: at once, in the tick.
    """

    __slots__ = ("executor", "_job", "_then")

    def __init__(self) -> None:
        self.executor: Executor | None = None
        self._job: Future | None = None
        self._then: Callable[[Any], object] | None = None

    @property
    def busy(self) -> bool:
        """A job is in flight (started, its answer not taken yet)."""
        return self._job is not None

    def start(self, job: Callable[[], Any], then: Callable[[Any], object]) -> None:
        """Run ``job`` off the tick and ``then(answer)`` in the first tick :meth:`poll` finds it done; without an
        :attr:`executor`, both now (``then``'s return value is ignored). A job still in flight is forgotten."""
        self.drop()
        if self.executor is None:
            then(job())
            return
        self._job, self._then = self.executor.submit(job), then

    def poll(self) -> bool:
        """True when no job is in flight; a job found done has its ``then`` called first (an exception the job
        raised is raised here, in the tick, as if the job had run in it)."""
        job, then = self._job, self._then
        if job is None or then is None:
            return True
        if not job.done():
            return False
        self.drop()
        then(job.result())
        return True

    def drop(self) -> None:
        """Forget the job in flight: another motion started, its answer is of no use."""
        self._job = self._then = None
