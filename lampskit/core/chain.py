"""The chain of learned MPs over the stains, one control tick at a time (ruckig style).

The one implementation of MP chaining: the controller's skill executor steps
it at 1 kHz against perception's kappa, and :func:`lampskit.core.rollout.rollout`
(``lamps plan``, the figures, the benchmarks and tests) steps it offline with
a stand-in for kappa, so what is plotted is what the robot runs.

:class:`MpChain` drives the in-plane reference while the pad wipes:

* TRANSIT into stain j: the learned transitional MP from the current
  reference state (position, velocity, acceleration) into the periodic MP
  of j at the entry phase (:func:`~lampskit.core.planner.plan_transition`),
  so the reference is continuous in acceleration at both junctions.
* WIPE j: the periodic MP anchored at the stain's centre and scaled to its
  size, until the stain is done (kappa, vanished, or one pass of
  ``wipe_timeout_s`` or ``pass_cycles`` cycles, whichever comes first); a stain that moves meanwhile moves the anchor
  through the MP's ramp (:meth:`MpChain.adapt`). With adaptive wiping
  (:attr:`PlannerParams.adaptive`) the MP follows the ink that remains:
  anchor at its centre, r shrinking with its extent, the stroke stretched
  and turned to its shape, Omega as fast as the bounds allow at that r
  (:func:`~lampskit.core.planner.adapted_wipe`), every change through the
  runner's critically damped ramps.
* LEAVE j: re-planned over the stains open *now* (appeared, vanished or
  done ones included; with ``follow_plan`` the plan's own order instead, as
  the offline rollout runs it), the periodic MP runs on until its phase
  heads for the next stain (:func:`~lampskit.core.planner.exit_phase_delay`).
* REPLAN j (only with :attr:`MpChain.background`, the real-time loop): the
  re-plan runs on a planner thread, off the 1 kHz path, while the periodic
  MP goes on wiping j; the tick that finds it done hands it over and goes
  on as LEAVE. Without it (lock-step: deterministic) the re-plan runs in
  the tick. So does the search for the next transition's duration within
  the kinematic bounds (:func:`~lampskit.core.kinematic_bounds.bounded_duration`,
  a few ms): in real time it runs on the planner thread during LEAVE, for
  the state the periodic MP will have at its exit phase, and the exit tick
  plans the transition from the real state with that duration (in the
  tick only if the thread is late: ``transitions_searched_in_tick``).

:meth:`MpChain.update` returns a :class:`ChainResult`; a runner's error
status or a failed plan is :attr:`ChainResult.ERROR` with the reason in
:attr:`MpChain.error`, never an exception."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Mapping
from concurrent.futures import Executor
from enum import IntEnum
from typing import Protocol

import numpy as np

from lampskit.core.chain_jobs import PlannerJobs
from lampskit.core.chain_pass import WipePass
from lampskit.core.periodic import periodic_state
from lampskit.core.periodic_runner import PeriodicRunner
from lampskit.core.planner import adapted_wipe, exit_phase_delay, plan, plan_transition
from lampskit.core.planner_types import Plan, PlannerParams, Stain, TransitionSpec, Wipe
from lampskit.core.skill import Skill
from lampskit.core.transitional_runner import TransitionalRunner
from lampskit.errors import PlanningError

log = logging.getLogger(__name__)


class Reference(Protocol):
    """The in-plane reference the chain reads and writes (the executor's setpoint): arrays of shape (2,) in the
    board plane [m, m/s, m/s^2]."""

    xy: np.ndarray
    v_xy: np.ndarray
    a_xy: np.ndarray


class Book(Protocol):
    """What the chain asks about the stains (the executor's :class:`controller.stain_book.StainBook`, or the
    rollout's plan with a stand-in for kappa)."""

    max_passes: int

    @property
    def stains(self) -> Mapping[int, Stain]: ...  # the chain reads a stain's centre and the ink left

    def is_done(self, stain_id: int) -> bool: ...

    def end_pass(self, stain_id: int, clock_s: float) -> bool: ...

    def open_stains(self, clock_s: float, by_ink: bool = False, exclude: int | None = None) -> list[Stain]: ...

#: Adaptive wiping re-targets the periodic MP at most this often [s] (perception reports ~10-30 times a second)...
ADAPT_EVERY_S = 0.5
#: ...and only for a change of the anchor [m], of r or Omega (relative) or of the stroke (Frobenius) above these.
ADAPT_MIN_MOVE_M, ADAPT_MIN_RATIO, ADAPT_MIN_STROKE = 0.003, 0.08, 0.08


def _bounded_duration_of(skill: Skill, plan_: Plan, wipe: Wipe, start) -> float:
    """The planner thread's job: the duration of the transition from ``start`` into ``wipe``, within the bounds."""
    return plan_transition(skill, plan_, wipe, start).duration_s


#: How far [m] along :attr:`MpChain.finish_heading` the last stroke aims (far: a direction, not a point).
FINISH_LOOKOUT_M = 10.0


class ChainResult(IntEnum):
    """Result of :meth:`MpChain.start` and :meth:`MpChain.update` (negative = error)."""

    ERROR = -1  #: see :attr:`MpChain.error`; the reference was not written
    WORKING = 0
    TRANSITION = 1  #: a transitional MP started, into the stain of :attr:`MpChain.wipe` (a junction)
    WIPE = 2  #: the stain's periodic MP took over (a junction)
    FINISHED = 3  #: the last stain left at its exit phase; the reference was not written: bring it to rest


class ChainStep(IntEnum):
    """What the chain runs; :meth:`MpChain.update` calls one handler per step."""

    TRANSIT = 0  #: a transitional MP into the stain's periodic MP
    WIPE = 1  #: the periodic MP until the stain is done
    LEAVE = 2  #: the periodic MP until its phase heads for the next stain
    REPLAN = 3  #: the periodic MP while the re-plan runs on the planner thread


class MpChain:
    """Transitional and periodic MPs chained over the planned wipes. See the module docstring.

    Parameters
    ----------
    skill : Skill
    planner : PlannerParams
    wipe_timeout_s : float
        One pass over a stain without kappa lasts at most this long [s]...
    pass_cycles : float
        ... and at most this many cycles of the periodic MP (inf: no limit).
    counters : Counter
        Shared with the executor: ``replans``, ``wipe_timeouts``.
    follow_plan : bool
        After each stain go on with the plan's next open stain, in the plan's order (the offline rollout);
        False: re-plan over the stains open now (the executor).

    Attributes
    ----------
    wipe : Wipe or None
        The stain being wiped or transitioned to (while wiping adaptively: the running targets).
    step : ChainStep
    error : str
        Why the last :attr:`ChainResult.ERROR`.
    """

    def __init__(self, skill: Skill, planner: PlannerParams, wipe_timeout_s: float, counters: Counter[str],
                 follow_plan: bool = False, pass_cycles: float = np.inf) -> None:
        self.skill = skill
        self.follow_plan = follow_plan
        self.planner = planner
        self.wipe_timeout_s = wipe_timeout_s
        self.pass_cycles = pass_cycles
        self.counters = counters
        self.wipe: Wipe | None = None
        self.step = ChainStep.TRANSIT
        self.error = ""
        self._runner: TransitionalRunner | PeriodicRunner | None = None
        self._plan: Plan | None = None
        self._entry: TransitionSpec | None = None
        self._next: Wipe | None = None
        #: (2,) unit direction [board frame] the last stroke heads in when the chain finishes, so the stop that
        #: follows runs that way (the executor: away from the robot base, where the arm has room); None: at once
        self.finish_heading: np.ndarray | None = None
        self._jobs = PlannerJobs()
        self._pass = WipePass()
        self._on_step = {ChainStep.TRANSIT: self._on_transit, ChainStep.WIPE: self._on_wipe,
                         ChainStep.LEAVE: self._on_leave, ChainStep.REPLAN: self._on_replan}

    @property
    def background(self) -> Executor | None:
        """Where re-plans run (a one-thread executor), or None: in the tick."""
        return self._jobs.executor

    @background.setter
    def background(self, executor: Executor | None) -> None:
        self._jobs.executor = executor

    @property
    def entry(self) -> TransitionSpec | None:
        """The spec of the last transition started (into :attr:`wipe`)."""
        return self._entry

    @property
    def cycles_wiped(self) -> float:
        """Cycles of the periodic MP run on the current stain since its transition ended (0 before)."""
        if self.step == ChainStep.TRANSIT:
            return 0.0
        return (self._periodic().phase_unwrapped_rad - self._pass.phase0_rad) / (2 * np.pi)

    @property
    def current_mp(self) -> str:
        """``"transitional k"`` or ``"periodic k"``: the MP running."""
        if self.step == ChainStep.TRANSIT:
            return f"transitional {self._spec().transitional_index}"
        return f"periodic {self._wiping().periodic_index}"

    # ------------------------------------------------------------------ what each step has (set by start)
    def _periodic(self) -> PeriodicRunner:
        """The stain's periodic MP runner (steps WIPE, LEAVE, REPLAN)."""
        runner = self._runner
        if not isinstance(runner, PeriodicRunner):
            raise RuntimeError(f"MpChain: no periodic MP runs in step {self.step.name}")
        return runner

    def _transitional(self) -> TransitionalRunner:
        """The transition's runner (step TRANSIT)."""
        runner = self._runner
        if not isinstance(runner, TransitionalRunner):
            raise RuntimeError(f"MpChain: no transitional MP runs in step {self.step.name}")
        return runner

    def _wiping(self) -> Wipe:
        """:attr:`wipe`, once started."""
        if self.wipe is None:
            raise RuntimeError("MpChain: not started")
        return self.wipe

    def _spec(self) -> TransitionSpec:
        """The spec of the last transition started."""
        if self._entry is None:
            raise RuntimeError("MpChain: not started")
        return self._entry

    def _current_plan(self) -> Plan:
        """The plan the chain follows, once started."""
        if self._plan is None:
            raise RuntimeError("MpChain: not started")
        return self._plan

    def start(self, plan_: Plan, reference: Reference) -> ChainResult:
        """Into the plan's first wipe from the reference's in-plane state: TRANSITION or ERROR."""
        self._jobs.drop()  # a re-plan of a chain left earlier (a stop, a fault): of no use
        self._plan = plan_
        return self._start_transition(plan_.wipes[0], reference)

    def update(self, dt_s: float, reference: Reference, book: Book, clock_s: float) -> ChainResult:
        """Advance by ``dt_s`` [s] at ``clock_s`` [s] and write the in-plane reference (not on ERROR or FINISHED).

        A transition starting in this tick starts from ``reference`` as the
        previous tick left it.
        """
        result = self._on_step[self.step](dt_s, reference, book, clock_s)
        if result == ChainResult.ERROR or result == ChainResult.FINISHED:
            return result
        r = self._transitional() if self.step == ChainStep.TRANSIT else self._periodic()
        reference.xy[:], reference.v_xy[:], reference.a_xy[:] = r.position_m, r.velocity_m_s, r.acceleration_m_s2
        return result

    def adapt(self, book: Book, clock_s: float) -> ChainResult | None:
        """A fresh view while wiping at ``clock_s`` [s]: adaptive wiping re-targets the periodic MP at the ink
        that remains (see the module docstring); fixed wiping re-anchors it (through its ramp) at the stain's
        centre if that moved over 2 mm. None if nothing changed."""
        if self.step != ChainStep.WIPE:
            return None
        old, runner, planned = self._wiping(), self._periodic(), self._pass.planned
        if planned is None:
            raise RuntimeError("MpChain: wiping without the wipe as planned")
        s = book.stains.get(old.stain.id)
        if s is None:
            return None
        if not self.planner.adaptive:
            if not np.linalg.norm(s.centre_m - runner.anchor_m) > 0.002:
                return None
            return self._checked(runner.set_targets(anchor_m=s.centre_m))
        if s.ink is None or clock_s - self._pass.adapted_at_s < ADAPT_EVERY_S:
            return None
        new = adapted_wipe(self.skill, planned, old, s.ink, self.planner)
        eye = np.eye(2)
        stroke_change = np.linalg.norm((eye if new.stroke is None else new.stroke)
                                       - (eye if old.stroke is None else old.stroke))
        if not (np.linalg.norm(new.anchor_m - old.anchor_m) > ADAPT_MIN_MOVE_M
                or abs(new.amplitude_m / old.amplitude_m - 1.0) > ADAPT_MIN_RATIO
                or abs(new.omega_rad_s / old.omega_rad_s - 1.0) > ADAPT_MIN_RATIO
                or stroke_change > ADAPT_MIN_STROKE):
            return None
        self._pass.adapted_at_s = clock_s
        self.counters["adaptations"] += 1
        self.wipe = new
        stroke = new.stroke if new.stroke is not None else (eye if old.stroke is not None else None)
        return self._checked(runner.set_targets(anchor_m=new.anchor_m, amplitude_m=new.amplitude_m,
                                                omega_rad_s=new.omega_rad_s, stroke=stroke))

    # ------------------------------------------------------------------ one handler per step
    def _on_transit(self, dt_s: float, reference: Reference, book: Book, clock_s: float) -> ChainResult:
        runner = self._transitional()
        status = runner.update(dt_s)
        if status < 0:
            return self._checked(status)
        if runner.finished:
            return self._start_wipe(runner.overrun_s)
        return ChainResult.WORKING

    def _wipe_on(self, dt_s: float) -> ChainResult | None:
        """The stain's periodic MP ``dt_s`` [s] further (WIPE and REPLAN); ERROR on a runner error, else None."""
        status = self._periodic().update(dt_s)
        if status < 0:
            return self._checked(status)
        self._pass.t_s += dt_s
        return None

    def _on_wipe(self, dt_s: float, reference: Reference, book: Book, clock_s: float) -> ChainResult:
        runner = self._periodic()
        if (failed := self._wipe_on(dt_s)) is not None:
            return failed
        if not self._pass_over(book, clock_s):
            return ChainResult.WORKING
        if self._choose_next(runner, book, clock_s) == ChainResult.ERROR:
            return ChainResult.ERROR
        if self.step == ChainStep.REPLAN:
            return ChainResult.WORKING
        return self._leave_when_due(runner, reference)

    def _on_leave(self, dt_s: float, reference: Reference, book: Book, clock_s: float) -> ChainResult:
        runner = self._periodic()
        status = runner.update(dt_s)
        if status < 0:
            return self._checked(status)
        return self._leave_when_due(runner, reference)

    # ------------------------------------------------------------------ hand-overs
    def _start_transition(self, wipe: Wipe, reference: Reference) -> ChainResult:
        r = reference
        duration, late = self._jobs.take_duration()
        if late:
            self.counters["transitions_searched_in_tick"] += 1
        try:
            spec = plan_transition(self.skill, self._current_plan(), wipe,
                                   (r.xy.copy(), r.v_xy.copy(), r.a_xy.copy()), duration)
            runner = TransitionalRunner(self.skill.transitional[spec.transitional_index].mp, spec.start, spec.goal,
                                        spec.duration_s, forcing_transform=spec.forcing_transform)
        except PlanningError as exc:
            return self._failed(f"cannot plan the transition to stain {wipe.stain.id}: {exc}")
        self._runner, self._entry, self.wipe = runner, spec, wipe
        self.step = ChainStep.TRANSIT
        return ChainResult.TRANSITION

    def _start_wipe(self, overrun_s: float) -> ChainResult:
        """The stain's periodic MP from where the transition ended, ``overrun_s`` [s] into its motion."""
        wipe, entry = self._wiping(), self._spec()
        try:
            runner = PeriodicRunner(self.skill.periodic[wipe.periodic_index].mp, wipe.anchor_m, wipe.amplitude_m,
                                    wipe.omega_rad_s, entry.entry_phase_rad, start_position_m=entry.goal[0],
                                    start_velocity_m_s=entry.goal[1], stroke=wipe.stroke)
        except PlanningError as exc:
            return self._failed(f"cannot start the periodic MP {wipe.periodic_index} on stain {wipe.stain.id}: {exc}")
        self._runner = runner
        self._pass.begin(wipe, runner.phase_unwrapped_rad)
        self.step = ChainStep.WIPE
        if overrun_s > 0.0:
            status = runner.update(overrun_s)
            if status < 0:
                return self._checked(status)
        return ChainResult.WIPE

    def _pass_over(self, book: Book, clock_s: float) -> bool:
        """The stain has kappa, has vanished, or this pass is over (``wipe_timeout_s`` or ``pass_cycles``; then it
        waits for a recheck)."""
        sid = self._wiping().stain.id
        if book.is_done(sid):
            return True
        cycles = self.cycles_wiped
        if self._pass.t_s < self.wipe_timeout_s and cycles < self.pass_cycles:
            return False
        self.counters["wipe_timeouts"] += 1  # a pass ended without kappa (by time or by cycles)
        if cycles >= self.pass_cycles:
            self.counters["passes_ended_by_cycles"] += 1
        if book.end_pass(sid, clock_s):
            log.warning("stain %d: no kappa after %d passes, giving up", sid, book.max_passes)
        else:
            log.info("stain %d: no kappa after %.1f s (%.1f cycles), back to it later", sid, self._pass.t_s, cycles)
        return True

    def _choose_next(self, runner: PeriodicRunner, book: Book, clock_s: float) -> ChainResult:
        """Re-plan over the stains open now (in the tick, or handed to :attr:`background`); keep wiping until
        the phase heads for the next one."""
        current = self._wiping().stain.id
        open_stains = book.open_stains(clock_s, by_ink=self.planner.adaptive, exclude=current)
        self._next = None
        if not open_stains:
            return self._leave_towards(runner, None)
        if self.follow_plan:  # the plan's next open stains, in its order
            followed = self._current_plan()
            ids, wipes = {s.id for s in open_stains}, followed.wipes
            k = next((i for i, w in enumerate(wipes) if w.stain.id == current), -1)
            rest = tuple(w for w in wipes[k + 1:] + wipes[:max(k, 0)] if w.stain.id in ids)
            return self._leave_towards(runner, Plan(rest, followed.params) if rest else None)
        start = runner.position_m.copy()
        if self._jobs.executor is not None:
            self._jobs.replan = self._jobs.executor.submit(plan, self.skill, open_stains, start, self.planner)
            self.step = ChainStep.REPLAN
            return ChainResult.WORKING
        try:
            new_plan = plan(self.skill, open_stains, start, self.planner)
        except PlanningError as exc:
            return self._failed(f"planning failed: {exc}")
        return self._leave_towards(runner, new_plan)

    def _on_replan(self, dt_s: float, reference: Reference, book: Book, clock_s: float) -> ChainResult:
        """Wipe on while the planner thread works; take its plan at the first tick it is done."""
        runner = self._periodic()
        if (failed := self._wipe_on(dt_s)) is not None:
            return failed
        pending = self._jobs.replan
        if pending is None or not pending.done():
            self.counters["ticks_waiting_for_a_plan"] += 1
            return ChainResult.WORKING
        self._jobs.replan = None
        try:
            new_plan = pending.result()
        except PlanningError as exc:
            return self._failed(f"planning failed: {exc}")
        except Exception as exc:  # a bug in the planner thread is a failed plan, not a dead loop
            return self._failed(f"planning failed: {type(exc).__name__}: {exc}")
        if self._leave_towards(runner, new_plan) == ChainResult.ERROR:
            return ChainResult.ERROR
        return self._leave_when_due(runner, reference)

    def _leave_towards(self, runner: PeriodicRunner, new_plan: Plan | None) -> ChainResult:
        """LEAVE: the periodic MP runs on until its phase heads for the plan's first stain (or ends the chain)."""
        towards = None
        if new_plan is not None:
            self._plan = new_plan
            self.counters["replans"] += 1
            self._next = new_plan.wipes[0]
            towards = self._next.anchor_m
        elif self.finish_heading is not None:
            towards = runner.anchor_m + FINISH_LOOKOUT_M * self.finish_heading
        wipe = self._wiping()
        delay = 0.0 if towards is None else exit_phase_delay(self.skill, wipe, runner.phase_rad, towards)
        self._pass.leave_at_rad = runner.phase_unwrapped_rad + delay
        self.step = ChainStep.LEAVE
        jobs = self._jobs
        jobs.duration = None
        if jobs.executor is not None and self._next is not None:
            # the state at the exit phase, on the limit cycle the runner follows: what the transition starts from
            mp = self.skill.periodic[wipe.periodic_index].mp
            exit_state = periodic_state(mp, runner.phase_rad + delay, runner.anchor_m.copy(), runner.amplitude_m,
                                        runner.omega_rad_s, None if wipe.stroke is None else runner.stroke)
            jobs.duration = jobs.executor.submit(_bounded_duration_of, self.skill, self._current_plan(), self._next,
                                                 tuple(np.array(x) for x in exit_state))
        return ChainResult.WORKING

    def _leave_when_due(self, runner: PeriodicRunner, reference: Reference) -> ChainResult:
        """Once the phase reaches the exit phase: into the next stain, or FINISHED after the last."""
        if runner.phase_unwrapped_rad < self._pass.leave_at_rad:
            return ChainResult.WORKING
        if self._next is None:
            return ChainResult.FINISHED
        return self._start_transition(self._next, reference)

    def _checked(self, status: IntEnum) -> ChainResult:
        """WORKING for a good runner status; an error (negative) is ERROR naming the MP and the status."""
        if status < 0:
            return self._failed(f"{self.current_mp} MP step failed: {status.name}")
        return ChainResult.WORKING

    def _failed(self, reason: str) -> ChainResult:
        self.error = reason
        return ChainResult.ERROR
