"""The LAMPS skill executor (paper section II-C): phases, MP chaining, re-planning, safety reactions.

Pure logic, no I/O: every tick :meth:`SkillExecutor.step` takes the tool's
measured state and returns a :class:`Setpoint`, both in the board frame
(:mod:`controller.executor_types`); stains, e-stops and faults come in
through methods. The MPs move ``xy`` in the board plane; approach, lift-off
and the air mode move the height ``h`` too; in contact the normal
direction is force-regulated and ``h`` is unused.

A state machine over :class:`~interfaces.messages.Phase` (what the cell
sees) and :class:`Stage` (the motion running inside a phase, one handler
each; the motions are :mod:`controller.free_motion` and the MP chain
:mod:`lampskit.core.chain`): INIT -> WAIT_PEERS -> APPROACH -> TRANSITION(i)
-> WIPE(i) -> TRANSITION(i -> j) -> ... -> RETREAT -> DONE, with
PAUSED(reason), FAULT(reason) and ESTOP reachable from any phase.

* APPROACH: first (after each start of the robot) a survey: fly to
  ``standoff_m`` above the look point of the whole board, where the arm
  hides none of it from the camera, and wait ``survey_s`` for the stains
  (none seen: once more from where the arm hides what it hid there);
  then plan and fly (quintic, pad turning flat) to ``standoff_m`` above the
  first stain of the plan, descend until the measured force passes
  ``contact_threshold_n``, ramp the force up to its target.
* TRANSITION(j), WIPE(j): the learned MPs chained over the stains
  (:mod:`lampskit.core.chain`): continuous in acceleration at every junction,
  re-planned over the stains open whenever the next one is picked, the
  anchor following a stain that moves; a stain left without kappa waits
  for a recheck (:mod:`controller.stain_book`).
* RETREAT: the in-plane motion is brought to rest C2-continuously, the
  force ramps down, the pad lifts to ``standoff_m``; with stains still
  waiting for kappa it then flies to a look point (off them, on the
  robot base's side, so the arm does not hide them from the camera) and
  waits ``recheck_s`` there; DONE holds and re-approaches if stains open.
* PAUSED / FAULT / ESTOP: the in-plane motion brakes to rest, the force
  ramps down (fast on an e-stop), the pad lifts off and holds. PAUSED
  resumes by itself when stains are fresh again; FAULT and ESTOP wait for
  :meth:`clear` (an e-stop release), except a lost robot, which the
  service restarts with :meth:`restart` when states come back. Released
  before the pad is off (an e-stop's lift stands still while the robot
  side holds the arm), the lift finishes PAUSED, no longer ESTOP.

An MP runner's step that reports an error (a negative status) is a FAULT
naming the MP and the status, never an exception in the loop.
"""

from __future__ import annotations

import logging
from collections import Counter

import numpy as np

from interfaces.messages import Phase
from lampskit.core.chain import ChainResult, MpChain
from lampskit.core.planner import plan
from lampskit.core.planner_types import Plan, PlannerParams, Stain
from lampskit.core.skill import Skill
from lampskit.errors import PlanningError

from .board_watch import BoardWatch, Jump
from .executor_stage import ACTIVE, HALTED, LIFTED_M, RELEASED_N, Stage
from .executor_starts import BoardSurvey, StartLatches
from .executor_state import ExecutorState
from .executor_stops import ExecutorStops
from .executor_types import BoardPose, Setpoint, ToolState
from .free_motion import FreeMotion
from .params import ExecutorParams, ForceParams
from .stain_book import StainBook
from .surface_touch import SurfaceTouch

log = logging.getLogger(__name__)

#: The reason of PAUSED after an e-stop or fault released before its stop had lifted the pad off (:meth:`clear`).
RELEASED_LIFTING = "released: lifting off before going on"


class SkillExecutor:
    """Runs one skill over the stains it is told about. See the module docstring for the phases.

    Parameters
    ----------
    skill : Skill
    params : ExecutorParams
    force : ForceParams
    planner : PlannerParams

    Attributes
    ----------
    state : ExecutorState
        The run's state, shared with its parts: ``watch`` (:class:`BoardWatch`, the board reports) and ``stops``
        (:class:`ExecutorStops`, the retreat, the stops, the look); :attr:`phase` and the rest read it.
    counters : Counter
        Events for status (replans, wipe timeouts, junctions, ...).
    junction_ticks : list of int
        Tick numbers at which one MP handed over to the next (for continuity checks).
    """

    def __init__(self, skill: Skill, params: ExecutorParams | None = None, force: ForceParams | None = None,
                 planner: PlannerParams | None = None) -> None:
        self.skill = skill
        self.p = params or ExecutorParams()
        self.f = force or ForceParams()
        self.planner = planner or PlannerParams()
        self.counters: Counter[str] = Counter()
        self.junction_ticks: list[int] = []
        self.state = ExecutorState(log, self.counters, self.junction_ticks)
        self.book = StainBook(self.p.recheck_s, self.p.max_passes)
        self.stains_fresh = False
        self.motion = FreeMotion(self.p, self.f, self.counters)
        self.surface = SurfaceTouch(self.p.first_creep_height_m + self.p.contact_search_m)  # touches place it
        self.chain = MpChain(skill, self.planner, self.p.wipe_timeout_s, self.counters, pass_cycles=self.p.pass_cycles)
        self.stops = ExecutorStops(self.state, self.motion, self.book, self.p, self.f, self.planner)
        self.watch = BoardWatch(self.state, self.motion, self.surface, self.book, self.stops, self.p)
        self._sp = self.motion.setpoint
        self._plan: Plan | None = None
        self._latches = StartLatches()
        self._survey = BoardSurvey()
        self._on_stage = {Stage.FLY: self._on_fly, Stage.DESCEND: self._on_descend, Stage.CREEP: self._on_creep,
                          Stage.PRESS: self._on_press, Stage.CHAIN: self._on_chain, Stage.UNPRESS: self._on_unpress,
                          Stage.BRAKE: self._on_brake, Stage.LIFT: self._on_lift, Stage.HOLD: self._on_hold,
                          Stage.LOOK: self._on_look, Stage.SURVEY: self._on_survey}
        self._on_chain_result = {ChainResult.TRANSITION: self._entered_transition,
                                 ChainResult.WIPE: self._entered_wipe, ChainResult.FINISHED: self.stops.begin_retreat,
                                 ChainResult.ERROR: self._chain_failed}

    # ------------------------------------------------------------------ the state, as the cell sees it
    @property
    def phase(self) -> Phase:
        """What the cell sees."""
        return self.state.phase

    @property
    def reason(self) -> str:
        """Why the phase (set in PAUSED, FAULT, ESTOP)."""
        return self.state.reason

    @property
    def current_mp(self) -> str:
        """``"periodic k"``, ``"transitional k"``, ``"approach"``, ``"lift"``, ... for status."""
        return self.state.current_mp

    @property
    def stain_id(self) -> int:
        """The stain being wiped or approached (-1 none)."""
        return self.state.stain_id

    @property
    def board(self) -> BoardPose | None:
        """The adopted board (None until a board report in reach)."""
        return self.state.board

    @property
    def board_note(self) -> str:
        """Why the last board report was not taken ("" none; status)."""
        return self.watch.note

    @property
    def clock_s(self) -> float:
        """The skill's clock [s]: the sum of the steps' ``dt_s``."""
        return self.state.clock_s

    @property
    def ticks(self) -> int:
        """Steps and waits so far."""
        return self.state.ticks

    # ------------------------------------------------------------------ inputs
    def set_stains(self, board: BoardPose, stains: list[Stain]) -> None:
        """A fresh view of the board and its stains (kappa per stain).

        A board out of the arm's reach is refused; one that jumps from the adopted pose (beyond
        ``board_jump_m`` / ``board_jump_rad``) is not adopted and its stains are not taken (:meth:`BoardWatch.take`);
        a new stain out of the arm's reach is skipped (:meth:`BoardWatch.skip_out_of_reach`).
        """
        if not self.watch.take(board):
            return
        self.stains_fresh = True
        smeared_before = len(self.book.smeared)
        if self.book.update(stains, self.state.clock_s) and self.state.phase in ACTIVE:
            self.counters["stain_set_changes"] += 1
        for s in list(self.book.smeared.values())[smeared_before:]:
            self.counters["stains_smeared"] += 1
            log.warning("stain %d: smeared (%.0f %% left after %d passes without progress): moving on", s.id,
                        100.0 * s.remaining, s.passes)
        self.watch.skip_out_of_reach(stains)
        moved = self.chain.adapt(self.book, self.state.clock_s) if self.state.phase == Phase.WIPE else None
        if moved is not None:
            self.counters["anchor_moves"] += 1
            if moved == ChainResult.ERROR:
                self._chain_failed()

    def stains_stale(self, reason: str) -> None:
        """No stains update for too long: pause off the board (resumes on the next :meth:`set_stains`)."""
        self.stains_fresh = False
        if self.state.phase in ACTIVE:
            self.stops.stop(Phase.PAUSED, reason)

    def estop(self, reason: str) -> None:
        """E-stop: lift off (fast force ramp) and hold until :meth:`clear`; latched across restarts."""
        reason = reason or "e-stop"
        self.counters["estops"] += 1
        self._latches.estop = reason
        if self.state.phase != Phase.ESTOP or self.stops.resume_after_lift:  # not yet stopping, or already released
            self.stops.stop(Phase.ESTOP, reason, fast=True)
        else:
            self.state.reason = reason

    def fault(self, reason: str, at_the_arm: bool = False) -> None:
        """A fault (force cap, no contact found, planning failed): lift off, hold until :meth:`clear`.

        ``at_the_arm``: the arm does not follow the reference (a torque nothing explains): the stop starts from
        the pose last measured, at rest, not from the reference, which may have run ahead of the arm; braking that
        reference would keep the spring stretched between them and release it into the arm."""
        if self.state.phase not in HALTED:
            self.counters["faults"] += 1
            log.error("FAULT: %s", reason)
            if at_the_arm and self.state.last_tool is not None:
                self.motion.rest_at(self.state.last_tool)
            self.stops.stop(Phase.FAULT, reason)

    def clear(self) -> None:
        """Release an e-stop or a fault: re-approach the open stains (PAUSED while they are stale, DONE if none).

        A stop that has not lifted off yet (its motion stood still while the robot side held the arm) finishes its
        lift first, PAUSED (:data:`RELEASED_LIFTING`): the e-stop or fault is over, and a watcher that ends a run
        held in ESTOP or FAULT must not count that lift as one."""
        self._latches.estop = None
        if self.state.phase in HALTED and self._latches.initialised:
            self.stops.resume_after_lift = True
            if self.state.stage == Stage.HOLD:
                self._resume()
            else:
                self.state.set_phase(Phase.PAUSED, RELEASED_LIFTING)

    def robot_lost(self, reason: str) -> None:
        """No robot to command: FAULT at once, no motion (nothing would execute it)."""
        if self.state.phase != Phase.FAULT or self.state.reason != reason:
            self.counters["faults"] += 1
            log.error("FAULT: %s", reason)
        self.state.set_phase(Phase.FAULT, reason)
        self.state.stage = Stage.HOLD
        self.motion.cancel_turn()

    @property
    def pad_down(self) -> bool:
        """The pad presses (by the setpoint, or by the measured force: ``RELEASED_N`` or more, whatever the board
        model says), or moves less than ``LIFTED_M`` above the board: stopping now would leave it there."""
        return self._latches.initialised and (self._sp.contact or self.state.last_force_n >= RELEASED_N
                                              or (self.state.stage != Stage.HOLD and self.state.last_h_m < LIFTED_M))

    def restart(self) -> None:
        """The robot came back after a loss: start over from WAIT_PEERS at the measured pose on the next step (and
        survey the board again: the arm may be anywhere)."""
        self._latches.restart_pending = True
        self._survey.forget()

    # ------------------------------------------------------------------ the tick
    def wait(self) -> None:
        """No board known yet (no stains ever received): report WAIT_PEERS (or a latched ESTOP); the caller holds."""
        self.state.ticks += 1
        if self._latches.estop is not None:
            self.state.set_phase(Phase.ESTOP, self._latches.estop)
        elif self.state.phase in (Phase.INIT, Phase.ESTOP):
            self.state.set_phase(Phase.WAIT_PEERS, "")

    def step(self, dt_s: float, tool: ToolState) -> Setpoint:
        """Advance by ``dt_s`` [s] given the measured tool (board frame); returns the setpoint (reused next tick).

        ``dt_s`` 0 holds the skill where it is (the setpoint unchanged).

        Needs a board (:meth:`set_stains` called once); until then call :meth:`wait`.
        """
        self.state.ticks += 1
        self.state.clock_s += dt_s
        self.state.last_h_m = tool.h
        self.state.last_force_n = tool.force_n
        self.state.last_tool = tool
        if not self._latches.initialised or self._latches.restart_pending:
            self._start_over(tool)
        if self.state.phase == Phase.WAIT_PEERS:
            if self.stains_fresh and self._latches.estop is None:
                self.motion.hold_here(tool)
                self._survey_or_start()
            return self._sp
        if dt_s <= 0.0:
            return self._sp  # the skill's clock stands still (the robot braked): nothing moves on
        self.motion.step_turn(dt_s)
        self._on_stage[self.state.stage](dt_s, tool)
        return self._sp

    def _start_over(self, tool: ToolState) -> None:
        """WAIT_PEERS holding the measured pose; a pad found pressing ramps out and lifts first."""
        self.motion.hold_here(tool)
        self._latches.initialised = True
        self._latches.restart_pending = False
        st = self.state
        st.phase, st.reason, st.current_mp, st.stain_id, st.stage = Phase.WAIT_PEERS, "", "", -1, Stage.HOLD
        if tool.force_n > self.f.contact_threshold_n and not self.p.air:
            self.motion.press_measured(tool.force_n)  # keep pressing what it measures, then ramp out and lift
            self.stops.stop(Phase.PAUSED, "robot back with the pad on the board: lifting off before re-approaching")
        if self._latches.estop is not None:
            self.stops.stop(Phase.ESTOP, self._latches.estop, fast=True)

    # ------------------------------------------------------------------ one handler per stage
    def _on_fly(self, dt: float, tool: ToolState) -> None:
        if not self.p.air and self.motion.met_board(tool.force_n, dt):  # met the board on the way: the touch
            self.counters["flights_touched"] += 1
            self.motion.stop_where_touched(tool)
            self._begin_press(tool)
        elif self.motion.move(dt) and not self.motion.turning and not self.motion.turn_half_if_cramped():
            self.motion.descend(first_touch=self.surface.untouched)
            self.state.current_mp, self.state.stage = "descend", Stage.DESCEND

    def _on_descend(self, dt: float, tool: ToolState) -> None:
        arrived = self.motion.move(dt)
        if self.p.air:
            if arrived:
                self._begin_chain()
        elif tool.force_n >= self.f.contact_threshold_n:
            self._begin_press(tool)
        elif arrived:
            self.motion.creep()
            self.state.stage = Stage.CREEP

    def _on_creep(self, dt: float, tool: ToolState) -> None:
        arrived = self.motion.move(dt)
        if tool.force_n >= self.f.contact_threshold_n:
            self._begin_press(tool)
        elif arrived:
            self.fault(f"no contact found {self.p.contact_search_m * 100:.0f} cm below the expected board "
                       "surface (is the board where the stains say?)")

    def _on_press(self, dt: float, tool: ToolState) -> None:
        if self.motion.ramp_force(dt):
            self._begin_chain()

    def _on_chain(self, dt: float, tool: ToolState) -> None:
        result = self.chain.update(dt, self._sp, self.book, self.state.clock_s)
        if result != ChainResult.WORKING:
            self._on_chain_result[result]()

    def _on_unpress(self, dt: float, tool: ToolState) -> None:
        if self.motion.unpress(dt):
            self.stops.begin_lift(tool)

    def _on_brake(self, dt: float, tool: ToolState) -> None:
        if self.motion.move(dt):
            self.stops.begin_lift(tool)

    def _on_lift(self, dt: float, tool: ToolState) -> None:
        if not self.motion.move(dt):
            return
        self.state.stage = Stage.HOLD
        if self.state.phase == Phase.RETREAT:
            if not self.stops.begin_look():
                self.stops.done()
        elif self.stops.resume_after_lift:  # released while lifting (PAUSED)
            self._resume()

    def _on_look(self, dt: float, tool: ToolState) -> None:
        if self.motion.move(dt):
            if not self.motion.stayed:  # (a look point chosen off the tick may be where the pad already was)
                self.book.looked_at(self.state.clock_s)  # perception gets its full recheck_s from here
            self.stops.done()

    def _on_survey(self, dt: float, tool: ToolState) -> None:
        survey, board = self._survey, self.state.board
        if survey.until_s == float("inf"):
            if self.motion.move(dt) and not self.motion.turning:
                if survey.again and self.motion.stayed:  # no second point sees more of the board
                    self._start_approach_or_done()
                    return
                survey.until_s = self.state.clock_s + self.p.survey_s  # perception's time to see the board
                self.state.current_mp = "survey: looking again" if survey.again else "survey: looking"
        elif self.state.clock_s >= survey.until_s:
            if not survey.again and board is not None and not self.book.open_stains(self.state.clock_s):
                survey.look_again()  # no stain seen: one may be under the pad or the wrist (look_points)
                self.counters["surveys_again"] += 1
                self.state.current_mp = "survey: again"
                self.motion.fly_to_survey_again(board)
                return
            self._start_approach_or_done()

    def _on_hold(self, dt: float, tool: ToolState) -> None:
        self.motion.rest_in_plane()
        if self.stops.lift_if_pressing(tool):  # a stop must end with the pad off the board
            return
        if self._confirm_jump():
            return
        if self.state.phase == Phase.PAUSED and self.stains_fresh:
            self._resume()
        elif self.state.phase == Phase.DONE and self.stains_fresh and self.book.open_stains(self.state.clock_s):
            self.counters["new_stains_after_done"] += 1
            self._start_approach_or_done()

    def _confirm_jump(self) -> bool:
        """Holding in the air: a jumped board pose that has held still long enough is adopted and surveyed (at once
        if PAUSED with fresh stains); True while one waits."""
        found = self.watch.confirm_jump()
        if found == Jump.ADOPTED:
            self._survey.forget()  # the new pose is surveyed before any approach
            if self.state.phase == Phase.PAUSED and self.stains_fresh and self._latches.estop is None:
                self._survey_or_start()
        return found == Jump.PENDING

    # ------------------------------------------------------------------ approach and the MP chain
    def _resume(self) -> None:
        if self._latches.estop is not None:
            return
        if not self.stains_fresh:
            self.state.set_phase(Phase.PAUSED, "waiting for fresh stains")
            self.state.stage, self.state.current_mp = Stage.HOLD, "hold"
            return
        self._start_approach_or_done()

    def _survey_or_start(self) -> None:
        """The first start after (re)starting: survey the board first (:attr:`ExecutorParams.survey_s`), so a stain
        the arm hid from the camera at its start pose is in the plan; later starts plan at once, and so does a start
        on a board whose every reported stain is already judged clean (a controller restarted after the job: it
        holds still, DONE)."""
        stains = self.book.stains.values()
        all_judged_clean = bool(stains) and all(st.kappa for st in stains)
        if self._survey.done or self.p.survey_s <= 0.0 or self.p.look_clearance_m <= 0.0 or self.state.board is None \
                or all_judged_clean:
            self._start_approach_or_done()
            return
        self._survey.begin()
        self.counters["surveys"] += 1
        self.state.set_phase(Phase.APPROACH, "")
        self.state.stain_id, self.state.current_mp = -1, "survey"
        self.motion.fly_to_survey(self.state.board)
        self.state.stage = Stage.SURVEY

    def _start_approach_or_done(self) -> None:
        """Plan over the open stains and fly to the first; DONE if nothing is left to wipe."""
        open_stains = self.book.open_stains(self.state.clock_s, by_ink=self.planner.adaptive)
        self.stops.resume_after_lift = False
        if not open_stains:
            self.stops.done()
            self.state.stain_id = -1
            return
        try:
            self._plan = plan(self.skill, open_stains, self._sp.xy.copy(), self.planner)
        except PlanningError as exc:
            self.counters["faults"] += 1
            log.error("FAULT: planning failed: %s", exc)
            self.state.set_phase(Phase.FAULT, f"planning failed: {exc}")
            self.state.stage = Stage.HOLD
            return
        self.counters["plans"] += 1
        first, board = self._plan.wipes[0], self.state.board
        assert board is not None, "a plan without a board"  # plans are made on the adopted board only
        self.state.set_phase(Phase.APPROACH, "")
        self.state.stain_id, self.state.current_mp = first.stain.id, "approach"
        if not self.motion.fly_to_hover(first.anchor_m, board):
            self.counters["hovers_lowered"] += 1  # the elbow near its limit at the standoff
        self.state.stage = Stage.FLY

    def _begin_press(self, tool: ToolState) -> None:
        """Contact found on the way down: press, and learn where the surface is (:mod:`controller.surface_touch`)."""
        self.motion.press(tool)
        self.state.current_mp, self.state.stage = "press", Stage.PRESS
        board = self.state.board
        if board is not None and (touched := self.surface.touched(board, tool.h)) is not board:
            self.motion.adopt_board(board, touched)
            self.state.board = touched
            self.counters["surface_touches"] += 1
            self.counters["surface_offset_um"] = round(self.surface.offset_m * 1e6)

    def _begin_chain(self) -> None:
        """First transition of the chain, from rest at the hover point, into the plan's first wipe. The last stroke
        will head away from the robot base before the retreat's stop (the stop runs on a few cm: towards the base,
        on a board near it, that is where the elbow folds to its limit; the tilted board's pad dipped into it at
        33 N)."""
        self.motion.rest_in_plane()
        board = self.state.board
        if board is not None:
            away = 0.5 * board.size_m - board.to_board(np.zeros(3))[:2]
            n = float(np.linalg.norm(away))
            self.chain.finish_heading = away / n if n > 1e-6 else None
        assert self._plan is not None, "the chain begun without a plan"
        self._on_chain_result[self.chain.start(self._plan, self._sp)]()

    def _entered_transition(self) -> None:
        self.state.set_phase(Phase.TRANSITION, "")
        self.state.current_mp = self.chain.current_mp
        wipe = self.chain.wipe
        assert wipe is not None, "a transition leads into a wipe"
        self.state.stain_id = wipe.stain.id
        self.junction_ticks.append(self.state.ticks)
        self.counters["transitions"] += 1
        self.state.stage = Stage.CHAIN

    def _entered_wipe(self) -> None:
        self.state.set_phase(Phase.WIPE, "")
        self.state.current_mp = self.chain.current_mp
        self.junction_ticks.append(self.state.ticks)

    def _chain_failed(self) -> None:
        self.fault(self.chain.error)
