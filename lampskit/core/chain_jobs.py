"""What :class:`~lampskit.core.chain.MpChain` hands to the planner thread, and the answers in flight
(:class:`PlannerJobs`)."""

from __future__ import annotations

from concurrent.futures import Executor, Future


class PlannerJobs:
    """The chain's jobs off the 1 kHz path.

    Attributes
    ----------
    executor : Executor or None
        Where re-plans and duration searches run (a one-thread executor), or None: in the tick.
    replan : Future or None
        The re-plan over the stains open now (a :class:`~lampskit.core.planner_types.Plan`), while in step REPLAN.
    duration : Future or None
        The next transition's duration within the kinematic bounds [s], searched during LEAVE.
    """

    __slots__ = ("executor", "replan", "duration")

    def __init__(self) -> None:
        self.executor: Executor | None = None
        self.replan: Future | None = None
        self.duration: Future | None = None

    def drop(self) -> None:
        """Forget the answers in flight (of a chain left earlier: a stop, a fault)."""
        self.replan = self.duration = None

    def take_duration(self) -> tuple[float | None, bool]:
        """The searched duration [s] if its job is done and did not fail, else None; and whether a job was asked
        for but is of no use (late or failed). The job is forgotten either way."""
        job, self.duration = self.duration, None
        if job is not None and job.done() and job.exception() is None:
            return job.result(), False
        return None, job is not None
