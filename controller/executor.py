"""The LAMPS skill executor (paper section II-C): phases, MP chaining, re-planning, safety reactions.

Pure logic, no I/O: every tick :meth:`SkillExecutor.step` takes the tool's
measured state and returns a :class:`Setpoint`; stains, e-stops and faults
come in through methods. Positions are in the *board frame* (DESIGN.md):
in-plane ``xy`` [m] (what the MPs move), height ``h`` [m] along the
outward normal above the board surface (what approach, lift-off and the
air mode move); while in contact the normal direction is force-regulated
and ``h`` is unused.

Phases (DESIGN.md): INIT -> WAIT_PEERS -> APPROACH -> WIPE(i) ->
TRANSITION(i -> j) -> ... -> RETREAT -> DONE, with PAUSED(reason),
FAULT(reason) and ESTOP reachable from any phase.

* APPROACH: fly (quintic, pad turning flat) to ``standoff_m`` above the
  first stain of the plan, descend until the measured force passes
  ``contact_threshold_n``, ramp the force up to its target.
* TRANSITION into stain j: the learned transitional MP from the current
  reference state (position, velocity, acceleration) into the periodic MP
  of j at the entry phase (:func:`~lampskit.core.planner.plan_transition`),
  so the reference is continuous in acceleration at both junctions.
* WIPE(i): the periodic MP re-anchored at the stain's centre and scaled to
  its size, until its kappa is set (or ``wipe_timeout_s``: one pass), then
  on until the phase heads for the next stain (:func:`exit_phase_delay`). A
  camera cannot see a stain under the eraser, so a stain left without kappa
  is passed over until ``recheck_s`` after the pass (perception looks at
  it meanwhile) and wiped again after the others, at most ``max_passes``
  times.
* Re-planning: whenever the executor picks the next stain it re-plans over
  the stains open *now* (appeared, vanished or done ones included); a stain
  that moves while it is wiped moves the MP's anchor through its ramp.
* RETREAT: the in-plane motion is brought to rest C2-continuously, the
  force ramps down, the pad lifts to ``standoff_m``; with stains still
  waiting for kappa it then flies to :func:`look_point` (off them, on the
  robot base's side, so the arm does not hide them from the camera) and
  waits ``recheck_s`` there; DONE holds and re-approaches if stains open.
* PAUSED / FAULT / ESTOP: the in-plane motion brakes to rest, the force
  ramps down (fast on an e-stop), the pad lifts off and holds. PAUSED
  resumes by itself when stains are fresh again; FAULT and ESTOP wait for
  :meth:`clear` (an e-stop release), except a lost robot, which the
  service restarts with :meth:`restart` when states come back.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from lampskit.errors import PlanningError
from lampskit.core.planner import Plan, PlannerParams, Stain, Wipe, exit_phase_delay, plan, plan_transition
from lampskit.core.periodic_runner import PeriodicRunner
from lampskit.core.skill import Skill
from lampskit.core.transitional_runner import TransitionalRunner
from interfaces.transforms import tool_rotation_on_board

from .motion import OrientationBlend, Quintic, brake_to_rest, orientation_duration, rest_to_rest
from .params import ExecutorParams, ForceParams

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BoardPose:
    """The board: ``R`` (3, 3) its axes in the world, ``origin_m`` (3,) its corner, ``size_m`` (2,)."""

    R: np.ndarray
    origin_m: np.ndarray
    size_m: np.ndarray

    @classmethod
    def from_transform(cls, T: np.ndarray, size_m) -> "BoardPose":
        T = np.asarray(T, float)
        return cls(T[:3, :3].copy(), T[:3, 3].copy(), np.asarray(size_m, float).reshape(2))

    @property
    def normal(self) -> np.ndarray:
        return self.R[:, 2]

    def to_board(self, p_world: np.ndarray) -> np.ndarray:
        """(3,) board coordinates (x, y, h) of a world point."""
        return (np.asarray(p_world, float) - self.origin_m) @ self.R

    def to_world(self, xyh: np.ndarray) -> np.ndarray:
        """(3,) world point of board coordinates (x, y, h)."""
        return self.origin_m + self.R @ np.asarray(xyh, float)

    def close_to(self, other: "BoardPose", tol_m: float = 0.005, tol_rad: float = 0.02) -> bool:
        moved = np.linalg.norm(self.origin_m - other.origin_m)
        turned = np.linalg.norm(self.R - other.R)  # ~ angle for small turns
        return bool(moved <= tol_m and turned <= tol_rad)


@dataclass(frozen=True)
class StainState:
    """One stain as the executor knows it: id, centre (2,) in the board plane [m], size [m], kappa (done)."""

    id: int
    centre_m: np.ndarray
    size_m: float
    kappa: bool


@dataclass
class ToolState:
    """The pad as measured, in the board frame: xy (2,), h [m], in-plane velocity (2,), height rate, force [N].

    R : (3, 3) pad orientation in the world; force_n : the board's push on
    the eraser along the outward normal (positive when pressing).
    """

    xy: np.ndarray
    h: float
    v_xy: np.ndarray
    v_h: float
    R: np.ndarray
    force_n: float


@dataclass
class Setpoint:
    """What the impedance and force control should do this tick (board frame, SI units).

    xy, v_xy, a_xy : in-plane reference (2,); h, v_h, a_h : reference along
    the normal (used when ``contact`` is False); R, omega, domega : pad
    orientation (3, 3) and its rates (3,), world axes; contact : regulate
    the normal force to ``force_n`` instead of tracking h.
    """

    xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    v_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    a_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    h: float = 0.0
    v_h: float = 0.0
    a_h: float = 0.0
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    domega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact: bool = False
    force_n: float = 0.0


#: An in-the-air stop takes at most this long [s] (its dip below the start height is <= 0.2 v T).
AIR_BRAKE_S = 0.1

# stages inside a phase
_FLY, _DESCEND, _PRESS, _RUN, _LEAVE, _BRAKE, _UNPRESS, _LIFT, _HOLD, _LOOK = range(10)
_ZERO2 = np.zeros(2)


def look_point(board: BoardPose, centres_m: list[np.ndarray], sizes_m: list[float], clearance_m: float) -> np.ndarray:
    """(2,) board point [m] from which the arm leaves ``centres_m`` (stains (2,), sizes [m]) in the camera's view.

    The arm runs from the pad back towards the robot base, so the pad goes
    ``clearance_m`` beyond the stains' extent in the direction of the base
    (its projection on the board plane; the world origin), clipped into the
    board. With the base right behind the stains: along board -x.
    """
    c = np.mean(np.asarray(centres_m, float), axis=0)
    reach = max(float(np.linalg.norm(np.asarray(x) - c)) + 0.5 * s for x, s in zip(centres_m, sizes_m))
    d = board.to_board(np.zeros(3))[:2] - c
    n = float(np.linalg.norm(d))
    d = d / n if n > 1e-6 else np.array([-1.0, 0.0])
    return np.clip(c + d * (reach + clearance_m), 0.0, board.size_m)


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
    phase, reason : str
        Current phase (one of interfaces.messages.PHASES) and why (set in PAUSED, FAULT, ESTOP).
    current_mp : str
        ``"periodic k"``, ``"transitional k"``, ``"approach"``, ``"lift"``, ... for status.
    stain_id : int
        Stain being wiped or approached (-1 none).
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
        self.phase = "INIT"
        self.reason = ""
        self.current_mp = ""
        self.stain_id = -1
        self.counters: Counter[str] = Counter()
        self.junction_ticks: list[int] = []
        self.ticks = 0
        self.board: BoardPose | None = None
        self.stains: dict[int, StainState] = {}
        self.stains_fresh = False
        self._given_up: set[int] = set()
        self._passes: Counter[int] = Counter()
        self._left_at: dict[int, float] = {}  # stain id -> clock at the end of a pass without kappa
        self.clock_s = 0.0
        self._sp = Setpoint()
        self._stage = _HOLD
        self._mover: Quintic | None = None
        self._turn: OrientationBlend | None = None
        self._xy_runner: TransitionalRunner | PeriodicRunner | Quintic | None = None
        self._wipe: Wipe | None = None
        self._plan: Plan | None = None
        self._next: Wipe | None = None
        self._leave_at = 0.0
        self._wipe_t = 0.0
        self._force_from = self._force_to = 0.0
        self._force_t, self._force_ramp_s = 0.0, 1.0
        self._after_lift = "DONE"
        self._initialised = False
        self._estop: str | None = None
        self._creep = False
        self._restart_pending = False

    # ------------------------------------------------------------------ inputs
    def set_stains(self, board: BoardPose, stains: list[StainState]) -> None:
        """A fresh view of the board and its stains (kappa per stain)."""
        if self.board is None:
            self.board = board
        elif not board.close_to(self.board):
            if self._stage == _HOLD and not self._sp.contact:
                # adopt the new board while holding; the held pose stays where it is in the world
                sp = self._sp
                xyh = board.to_board(self.board.to_world(np.array([*sp.xy, sp.h])))
                sp.xy[:], sp.h = xyh[:2], float(xyh[2])
                self.board = board
                self.counters["board_adopted"] += 1
            else:
                self.counters["board_moved"] += 1
        old_open = self._open_ids()
        self.stains = {s.id: s for s in stains}
        self.stains_fresh = True
        if self._open_ids() != old_open and self.phase in ("WIPE", "TRANSITION", "APPROACH"):
            self.counters["stain_set_changes"] += 1
        if self.phase == "WIPE" and self._wipe is not None:
            s = self.stains.get(self._wipe.stain.id)
            if s is not None and np.linalg.norm(s.centre_m - self._xy_runner.anchor_m) > 0.002:
                self._xy_runner.set_targets(anchor_m=s.centre_m)
                self.counters["anchor_moves"] += 1

    def stains_stale(self, reason: str) -> None:
        """No stains update for too long: pause off the board (resumes on the next :meth:`set_stains`)."""
        self.stains_fresh = False
        if self.phase in ("APPROACH", "WIPE", "TRANSITION"):
            self._stop("PAUSED", reason)

    def estop(self, reason: str) -> None:
        """E-stop: lift off (fast force ramp) and hold until :meth:`clear`; latched across restarts."""
        reason = reason or "e-stop"
        self.counters["estops"] += 1
        self._estop = reason
        if self.phase != "ESTOP" or self._after_lift == "APPROACH":  # not yet stopping, or already released
            self._stop("ESTOP", reason, fast=True)
        else:
            self.reason = reason

    def fault(self, reason: str) -> None:
        """A fault (force cap, no contact found, planning failed): lift off, hold until :meth:`clear`."""
        if self.phase not in ("FAULT", "ESTOP"):
            self.counters["faults"] += 1
            log.error("FAULT: %s", reason)
            self._stop("FAULT", reason)

    def clear(self) -> None:
        """Release an e-stop or a fault: re-approach the open stains (PAUSED while they are stale, DONE if none)."""
        self._estop = None
        if self.phase in ("ESTOP", "FAULT") and self._initialised:
            self._after_lift = "APPROACH"
            if self._stage == _HOLD:
                self._resume()

    def _resume(self) -> None:
        if self._estop is not None:
            return
        if not self.stains_fresh:
            self._set_phase("PAUSED", "waiting for fresh stains")
            self._stage, self.current_mp = _HOLD, "hold"
            return
        self._start_approach_or_done()

    def robot_lost(self, reason: str) -> None:
        """No robot to command: FAULT at once, no motion (nothing would execute it)."""
        if self.phase != "FAULT" or self.reason != reason:
            self.counters["faults"] += 1
            log.error("FAULT: %s", reason)
        self._set_phase("FAULT", reason)
        self._stage = _HOLD
        self._turn = None

    def restart(self) -> None:
        """The robot came back after a loss: start over from WAIT_PEERS at the measured pose on the next step."""
        self._restart_pending = True

    # ------------------------------------------------------------------ the tick
    def wait(self) -> None:
        """No board known yet (no stains ever received): report WAIT_PEERS (or a latched ESTOP); the caller holds."""
        self.ticks += 1
        if self._estop is not None:
            self._set_phase("ESTOP", self._estop)
        elif self.phase in ("INIT", "ESTOP"):
            self._set_phase("WAIT_PEERS", "")

    def step(self, dt_s: float, tool: ToolState) -> Setpoint:
        """Advance by ``dt_s`` [s] given the measured tool (board frame); returns the setpoint (reused next tick).

        Needs a board (:meth:`set_stains` called once); until then call :meth:`wait`.
        """
        self.ticks += 1
        self.clock_s += dt_s
        if not self._initialised or self._restart_pending:
            self._hold_here(tool)
            self._initialised = True
            self._restart_pending = False
            self.phase, self.reason, self.current_mp, self.stain_id = "WAIT_PEERS", "", "", -1
            self._stage = _HOLD
            if tool.force_n > self.f.contact_threshold_n and not self.p.air:
                # back on a pressing pad: keep pressing what it measures, then ramp out and lift
                sp = self._sp
                sp.contact, sp.force_n = True, min(tool.force_n, self.f.target_n)
                self._stop("PAUSED", "robot back with the pad on the board: lifting off before re-approaching")
            if self._estop is not None:
                self._stop("ESTOP", self._estop, fast=True)
        if self.phase == "WAIT_PEERS":
            if self.stains_fresh and self._estop is None:
                self._hold_here(tool)
                self._start_approach_or_done()
            return self._sp
        self._advance(dt_s, tool)
        return self._sp

    # ------------------------------------------------------------------ phases
    def _advance(self, dt: float, tool: ToolState) -> None:
        sp, st = self._sp, self._stage
        if self._turn is not None:
            self._turn.update(dt)
            sp.R[:], sp.omega[:], sp.domega[:] = self._turn.R, self._turn.omega, self._turn.domega
            if self._turn.finished:
                self._turn = None
                sp.omega[:] = 0.0
                sp.domega[:] = 0.0
        if st == _FLY:
            self._move3(dt)
            if self._mover.finished and self._turn is None:
                self._begin_descend(tool)
        elif st == _DESCEND:
            self._move3(dt)
            if self.p.air:
                if self._mover.finished:
                    self._begin_chain(tool)
            elif tool.force_n >= self.f.contact_threshold_n:
                self._begin_press(tool)
            elif self._mover.finished and self._creep:
                self._begin_creep()
            elif self._mover.finished:
                self.fault(f"no contact found {self.p.contact_search_m * 100:.0f} cm below the expected board "
                           "surface (is the board where the stains say?)")
        elif st == _PRESS:
            if self._ramp_force(dt):
                self._begin_chain(tool)
        elif st in (_RUN, _LEAVE):
            self._run_chain(dt, tool)
        elif st == _BRAKE:
            if sp.contact:  # in-plane motion to rest while the force ramps out
                self._xy_runner.update(dt)
                self._copy_xy(self._xy_runner)
                done = self._ramp_force(dt) and self._xy_runner.finished
            else:  # in the air: x, y and h to rest together
                self._move3(dt)
                done = self._mover.finished
            if done:
                self._begin_lift(tool)
        elif st == _LIFT:
            self._move3(dt)
            if self._mover.finished:
                self._stage = _HOLD
                if self.phase == "RETREAT" and self._begin_look():
                    pass
                elif self.phase in ("RETREAT",):
                    self._set_phase("DONE", "")
                    self.current_mp = "hold"
                elif self._after_lift == "APPROACH" and self.phase in ("ESTOP", "FAULT"):
                    self._resume()
        elif st == _LOOK:
            self._move3(dt)
            if self._mover.finished:
                for sid in self._pending_ids():  # perception gets its full recheck_s from here
                    self._left_at[sid] = self.clock_s
                self._stage = _HOLD
                self._set_phase("DONE", "")
                self.current_mp = "hold"
        elif st == _HOLD:
            sp.v_xy[:] = sp.a_xy[:] = 0.0
            if self.phase == "PAUSED" and self.stains_fresh:
                self._resume()
            elif self.phase == "DONE" and self.stains_fresh and self._open_ids():
                self.counters["new_stains_after_done"] += 1
                self._start_approach_or_done()

    def _start_approach_or_done(self) -> None:
        """Plan over the open stains and fly to the first; DONE if nothing is left to wipe."""
        open_stains = self._open_stains()
        self._after_lift = "DONE"
        if not open_stains:
            self._set_phase("DONE", "")
            self._stage, self.current_mp, self.stain_id = _HOLD, "hold", -1
            return
        try:
            self._plan = plan(self.skill, open_stains, self._sp.xy.copy(), self.planner)
        except PlanningError as exc:
            self.counters["faults"] += 1
            log.error("FAULT: planning failed: %s", exc)
            self._set_phase("FAULT", f"planning failed: {exc}")
            self._stage = _HOLD
            return
        self.counters["plans"] += 1
        first = self._plan.wipes[0]
        self._next = first
        self._set_phase("APPROACH", "")
        self.stain_id, self.current_mp = first.stain.id, "approach"
        sp = self._sp
        start = np.array([*sp.xy, sp.h])
        goal = np.array([*first.anchor_m, self.p.standoff_m])
        self._mover = rest_to_rest(start, goal, self.p.approach_speed_m_s, 0.5)
        R_goal = tool_rotation_on_board(self.board.R)
        T_turn = max(orientation_duration(sp.R, R_goal, self.p.turn_rate_rad_s), self._mover.T, 0.3)
        self._turn = OrientationBlend(sp.R, R_goal, T_turn)
        sp.contact = False
        self._stage = _FLY

    def _begin_descend(self, tool: ToolState) -> None:
        """Down to ``creep_height_m`` at the approach speed, then creep towards (and past) the surface."""
        sp = self._sp
        if self.p.air:
            bottom = self.p.air_height_m
            T = max(abs(sp.h - bottom) / self.p.approach_speed_m_s, 0.3)
            self._creep = False
        else:
            bottom = min(self.p.creep_height_m, sp.h)
            T = max(abs(sp.h - bottom) / self.p.approach_speed_m_s, 0.2)
            self._creep = True
        self._mover = Quintic((np.array([*sp.xy, sp.h]), np.zeros(3), np.zeros(3)),
                              (np.array([*sp.xy, bottom]), np.zeros(3), np.zeros(3)), T)
        self.current_mp = "descend"
        self._stage = _DESCEND

    def _begin_creep(self) -> None:
        sp = self._sp
        bottom = -self.p.contact_search_m
        # a rest-to-rest quintic peaks at 1.875x its mean speed: mean = descend speed / 1.875
        T = abs(sp.h - bottom) * 1.875 / self.p.descend_speed_m_s
        self._mover = Quintic((np.array([*sp.xy, sp.h]), np.zeros(3), np.zeros(3)),
                              (np.array([*sp.xy, bottom]), np.zeros(3), np.zeros(3)), T)
        self._creep = False

    def _begin_press(self, tool: ToolState) -> None:
        sp = self._sp
        sp.v_xy[:] = sp.a_xy[:] = 0.0
        sp.h, sp.v_h, sp.a_h = tool.h, 0.0, 0.0
        sp.contact = True
        sp.force_n = min(max(tool.force_n, 0.0), self.f.target_n)
        self._start_force_ramp(self.f.target_n, self.f.ramp_s)
        self.current_mp = "press"
        self._stage = _PRESS

    def _start_force_ramp(self, target_n: float, ramp_s: float) -> None:
        self._force_from, self._force_to = self._sp.force_n, float(target_n)
        self._force_t, self._force_ramp_s = 0.0, float(ramp_s)

    def _ramp_force(self, dt: float) -> bool:
        """Smoothstep the force target towards the ramp's goal; True once there."""
        self._force_t = min(self._force_t + dt / self._force_ramp_s, 1.0)
        s = self._force_t
        self._sp.force_n = self._force_from + (self._force_to - self._force_from) * s * s * (3.0 - 2.0 * s)
        return self._force_t >= 1.0

    def _begin_chain(self, tool: ToolState) -> None:
        """First transition of the chain, from rest at the hover point, into the plan's first wipe."""
        wipe = self._next
        self._sp.v_xy[:] = self._sp.a_xy[:] = 0.0
        self._start_transition(wipe)

    def _start_transition(self, wipe: Wipe) -> None:
        sp = self._sp
        try:
            spec = plan_transition(self.skill, self._plan, wipe, (sp.xy.copy(), sp.v_xy.copy(), sp.a_xy.copy()))
        except PlanningError as exc:
            self.fault(f"cannot plan the transition to stain {wipe.stain.id}: {exc}")
            return
        self._xy_runner = TransitionalRunner(self.skill.transitional[spec.transitional_index].mp, spec.start,
                                             spec.goal, spec.duration_s, forcing_transform=spec.forcing_transform)
        self._spec = spec
        self._wipe = wipe
        self._set_phase("TRANSITION", "")
        self.current_mp = f"transitional {spec.transitional_index}"
        self.stain_id = wipe.stain.id
        self.junction_ticks.append(self.ticks)
        self.counters["transitions"] += 1
        self._stage = _RUN

    def _start_wipe(self, overrun_s: float) -> None:
        wipe, spec = self._wipe, self._spec
        runner = PeriodicRunner(self.skill.periodic[wipe.periodic_index].mp, wipe.anchor_m, wipe.amplitude_m,
                                wipe.omega_rad_s, spec.entry_phase_rad, start_position_m=spec.goal[0],
                                start_velocity_m_s=spec.goal[1])
        if overrun_s > 0.0:
            runner.update(overrun_s)
        self._xy_runner = runner
        self._wipe_t = 0.0
        self._leave_at = np.inf
        self._set_phase("WIPE", "")
        self.current_mp = f"periodic {wipe.periodic_index}"
        self.junction_ticks.append(self.ticks)
        self._stage = _RUN

    def _run_chain(self, dt: float, tool: ToolState) -> None:
        runner = self._xy_runner
        runner.update(dt)
        if self.phase == "TRANSITION":
            if runner.finished:
                self._start_wipe(runner.overrun_s)
                runner = self._xy_runner
        else:
            self._wipe_t += dt
            if self._stage == _RUN:
                sid = self._wipe.stain.id
                s = self.stains.get(sid)
                done = s is None or s.kappa
                if not done and self._wipe_t >= self.p.wipe_timeout_s:
                    self.counters["wipe_timeouts"] += 1
                    self._passes[sid] += 1
                    self._left_at[sid] = self.clock_s
                    if self._passes[sid] >= self.p.max_passes:
                        self._given_up.add(sid)
                        log.warning("stain %d: no kappa after %d passes, giving up", sid, self._passes[sid])
                    else:
                        log.info("stain %d: no kappa after %.1f s, back to it later", sid, self._wipe_t)
                    done = True
                if done:
                    self._choose_next(runner)
            if self._stage == _LEAVE and runner.phase_unwrapped_rad >= self._leave_at:
                if self._next is None:
                    self._begin_retreat()
                    return
                self._start_transition(self._next)
                runner = self._xy_runner
        self._copy_xy(runner)

    def _choose_next(self, runner: PeriodicRunner) -> None:
        """Re-plan over the stains open now; keep wiping until the phase heads for the next one."""
        current = self._wipe.stain.id
        open_stains = [s for s in self._open_stains() if s.id != current]
        self._next = None
        towards = None
        if open_stains:
            try:
                self._plan = plan(self.skill, open_stains, runner.position_m.copy(), self.planner)
                self.counters["replans"] += 1
                self._next = self._plan.wipes[0]
                towards = self._next.anchor_m
            except PlanningError as exc:
                self.fault(f"planning failed: {exc}")
                return
        delay = 0.0 if towards is None else exit_phase_delay(self.skill, self._wipe, runner.phase_rad, towards)
        self._leave_at = runner.phase_unwrapped_rad + delay
        self._stage = _LEAVE

    def _begin_retreat(self) -> None:
        self._set_phase("RETREAT", "")
        self.current_mp = "retreat"
        self.stain_id = -1
        self.junction_ticks.append(self.ticks)
        self._brake(self.p.stop_s, self.f.ramp_s)

    def _stop(self, phase: str, reason: str, fast: bool = False) -> None:
        """Brake the in-plane motion, ramp the force out, lift off, hold (PAUSED, FAULT, ESTOP)."""
        sp = self._sp
        self._set_phase(phase, reason)
        self._after_lift = "HOLD"
        self.current_mp = "lift"
        if self._stage == _HOLD and not sp.contact:
            return
        if self._turn is not None:  # bring the turn to rest smoothly, where it is heading
            self._turn.stop(self.p.estop_ramp_s if fast else self.p.stop_s)
        self._brake(self.p.estop_ramp_s if fast else self.p.stop_s,
                    self.p.estop_ramp_s if fast else self.f.ramp_s)

    def _brake(self, duration_s: float, force_ramp_s: float) -> None:
        """Bring the reference to rest C2-continuously (in-plane in contact, with h in the air), force to 0."""
        sp = self._sp
        if sp.contact:
            self._xy_runner = brake_to_rest(sp.xy, sp.v_xy, sp.a_xy, duration_s)
            self._start_force_ramp(0.0, force_ramp_s)
        else:
            # in the air: stop within 0.1 s and never below the current height (a brake while
            # descending must not carry the pad on into the board)
            T = min(duration_s, AIR_BRAKE_S)
            p0, v0, a0 = np.array([*sp.xy, sp.h]), np.array([*sp.v_xy, sp.v_h]), np.array([*sp.a_xy, sp.a_h])
            goal = p0 + 0.5 * v0 * T
            goal[2] = max(goal[2], sp.h)
            self._mover = Quintic((p0, v0, a0), (goal, np.zeros(3), np.zeros(3)), T)
        self._stage = _BRAKE

    def _begin_look(self) -> bool:
        """Off the board's stains awaiting kappa, so that the arm does not hide them from the camera.

        After the last pass with stains still without kappa (waiting for
        ``recheck_s``), the pad flies at ``standoff_m`` to the board point
        ``look_clearance_m`` beyond their edge on the side of the robot base:
        the arm reaches back towards the base, away from them. False (no
        move) when nothing waits or the clearance is 0.
        """
        pending = [self.stains[i] for i in self._pending_ids()]
        if not pending or self.p.look_clearance_m <= 0.0 or self.board is None:
            return False
        goal = look_point(self.board, [s.centre_m for s in pending], [s.size_m for s in pending],
                          self.p.look_clearance_m)
        sp = self._sp
        if np.linalg.norm(goal - sp.xy) < 0.005:
            return False
        self._mover = rest_to_rest(np.array([*sp.xy, sp.h]), np.array([*goal, sp.h]), self.p.approach_speed_m_s, 0.5)
        self.current_mp = "look"
        self.counters["looks"] += 1
        self._stage = _LOOK
        return True

    def _pending_ids(self) -> list[int]:
        """Stains passed over without kappa, waiting to be looked at (not given up)."""
        return [i for i, s in self.stains.items() if not s.kappa and i in self._left_at and i not in self._given_up]

    def _begin_lift(self, tool: ToolState) -> None:
        sp = self._sp
        h0 = tool.h if sp.contact else sp.h
        v0 = 0.0 if sp.contact else sp.v_h
        sp.contact, sp.force_n = False, 0.0
        goal_h = max(self.p.standoff_m, h0)
        T = max(abs(goal_h - h0) / self.p.descend_speed_m_s, 0.3)
        self._mover = Quintic((np.array([*sp.xy, h0]), np.array([0.0, 0.0, v0]), np.zeros(3)),
                              (np.array([*sp.xy, goal_h]), np.zeros(3), np.zeros(3)), T)
        sp.h, sp.v_h, sp.a_h = h0, v0, 0.0
        if self.phase == "RETREAT":
            self.current_mp = "retreat"
        self._stage = _LIFT

    # ------------------------------------------------------------------ helpers
    def _move3(self, dt: float) -> None:
        m, sp = self._mover, self._sp
        m.update(dt)
        sp.xy[:] = m.position[:2]
        sp.v_xy[:] = m.velocity[:2]
        sp.a_xy[:] = m.acceleration[:2]
        sp.h, sp.v_h, sp.a_h = float(m.position[2]), float(m.velocity[2]), float(m.acceleration[2])

    def _copy_xy(self, runner) -> None:
        sp = self._sp
        if isinstance(runner, Quintic):
            sp.xy[:], sp.v_xy[:], sp.a_xy[:] = runner.position, runner.velocity, runner.acceleration
        else:
            sp.xy[:], sp.v_xy[:], sp.a_xy[:] = runner.position_m, runner.velocity_m_s, runner.acceleration_m_s2

    def _hold_here(self, tool: ToolState) -> None:
        """Setpoint = the measured pose, at rest."""
        sp = self._sp
        sp.xy[:], sp.h = tool.xy, tool.h
        sp.v_xy[:] = sp.a_xy[:] = 0.0
        sp.v_h = sp.a_h = 0.0
        sp.R[:] = tool.R
        sp.omega[:] = sp.domega[:] = 0.0
        sp.contact, sp.force_n = False, 0.0
        self._turn = None

    def _set_phase(self, phase: str, reason: str) -> None:
        if phase != self.phase or reason != self.reason:
            log.info("phase %s -> %s%s", self.phase, phase, f" ({reason})" if reason else "")
            self.counters[f"phase_{phase.lower()}"] += 1
        self.phase, self.reason = phase, reason

    def _in_contact_phase(self) -> bool:
        return self._sp.contact

    def _open_ids(self) -> set[int]:
        return {s.id for s in self._open_stains()}

    def _open_stains(self) -> list[Stain]:
        return [Stain(s.id, s.centre_m, s.size_m) for s in self.stains.values()
                if not s.kappa and s.id not in self._given_up
                and self.clock_s - self._left_at.get(s.id, -math.inf) >= self.p.recheck_s]
