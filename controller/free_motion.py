"""The skill executor's setpoint outside the MP chain: fly, descend, press, brake, lift off, one tick at a time.

:class:`FreeMotion` owns the :class:`~controller.executor_types.Setpoint`
(board frame) and the motions that move it when no learned MP does: a
quintic in (x, y, h) in the air (:mod:`controller.motion`), the pad's turn,
an in-plane brake while in contact and the force target's ramp. Each
``start`` method sets a motion up from the setpoint as it is, so the
reference stays continuous in acceleration; each step method advances it
by one tick and says whether it has arrived. Which motion runs when is the
executor's decision (:mod:`controller.executor`).
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from arm.pad_turn import half_turn_way, half_turned
from arm.reach import ArmReach, pad_reach_problem
from interfaces.transforms import tool_rotation_on_board
from lampskit.core.planner_types import Stain

from .executor_types import BoardPose, Setpoint, ToolState
from .look_points import look_point, resurvey_point, stain_targets, survey_point
from .motion import (
    OrientationBlend,
    Quintic,
    SmoothRamp,
    bounded_brake_to_rest,
    brake_above,
    brake_to_rest,
    orientation_duration,
    rest_to_rest,
    vertical_move,
)
from .off_tick import OffTick
from .params import ExecutorParams, ForceParams

#: An in-the-air stop takes at most this long [s] (its dip below the start height is <= 0.2 v T).
AIR_BRAKE_S = 0.1
#: A lift ends where the elbow stays at least this far from stretched straight [rad]: at A4 = 0 the arm's reach
#: ends and its Jacobian loses a rank, and a lift along a board's normal that points away from the robot runs
#: into it near the board's far edge (the arm then swings through the singular pose while the pad stands still).
STRETCH_ROOM_RAD = 0.3
#: ... but at least this far off the board [m], wherever that is.
MIN_LIFT_M = 0.015
#: The pad hovers over a stain only where the elbow stays this far from its limit [rad] (lower, down to
#: ``creep_height_m``, where it would not): beyond the controller's joint margin (``LimitParams.joint_margin_rad``,
#: 0.12), inside which the limit's repulsion holds the elbow off the hover pose. On random board 279 the pad then
#: waited 30 mm off its hover near the robot base and, when the descent brought the reference back in reach, sped
#: down at 0.1 m/s into the board's zone: the robot side's press-speed brake.
HOVER_ELBOW_ROOM_RAD = 0.15
#: Where no hover height down to ``creep_height_m`` leaves the elbow that room, the hover moves along the board, in
#: steps of this [m], away from the shoulder (towards it for a stretched elbow) ...
HOVER_SHIFT_STEP_M = 0.01
#: ... up to this far [m]; the descent touches there and the chain's transition slides to the stain in contact. On
#: random board 899 the pad flew to a corner stain's lowered hover 16 mm up with the elbow against its limit: the
#: limit held the elbow, the pad sank 14 mm under its reference onto the board at the flight's speed (22-29 N, the
#: robot side's press-speed brake 11 times).
HOVER_SHIFT_MAX_M = 0.2
#: A flight has met the board once the measured force has stayed at or over ``contact_threshold_n`` this long [s]
#: (a spike of the force estimate in a fast flight is not a touch; on board 899 the force passed 10 N 0.1 s in).
FLIGHT_TOUCH_S = 0.01


class FreeMotion:
    """The setpoint and its free motions. See the module docstring.

    Parameters
    ----------
    params : ExecutorParams
    force : ForceParams

    Attributes
    ----------
    setpoint : Setpoint
        Written in place every tick.
    arm : ArmReach or None
        The arm's elbow geometry: look points stay where the elbow has room (None: anywhere on the board).
    joints : (n,) [rad] or None
        The measured joint positions, updated in place every tick by the owner (None: not known; no half turn).
    joint_limits : ((n,), (n,)) [rad] or None
        The joints' position limits, as ``joints`` is given.
    aim : OffTick
        Where look points are chosen: its ``executor`` the planner thread in the real-time loop (the choice takes
        a few ms, bench/bench_look_points.py; the setpoint holds meanwhile and :meth:`move` reports not arrived),
        None: in the tick.
    stayed : bool
        The last look's point was where the pad already was: no move was made.
    """

    def __init__(self, params: ExecutorParams, force: ForceParams, counters: Counter[str] | None = None) -> None:
        self.p = params
        self.f = force
        self.counters: Counter[str] = Counter() if counters is None else counters
        self.arm: ArmReach | None = None
        self.joints: np.ndarray | None = None
        self.joint_limits: tuple[np.ndarray, np.ndarray] | None = None
        self.setpoint = Setpoint()
        self.aim = OffTick()
        self.stayed = False
        self._mover: Quintic | None = None  # x, y, h in the air (set by _start, which drops an aim in flight)
        self._turn: OrientationBlend | None = None
        self._xy_brake: Quintic | None = None  # x, y in contact
        self._force = SmoothRamp()
        self._force_over_s = 0.0  # how long a flight's force has stayed over the contact threshold [s]

    @property
    def turning(self) -> bool:
        return self._turn is not None

    # ------------------------------------------------------------------ starting a motion
    def hold_here(self, tool: ToolState) -> None:
        """Setpoint = the measured pose, at rest, in the air."""
        self.aim.drop()
        sp = self.setpoint
        sp.xy[:], sp.h = tool.xy, tool.h
        sp.v_xy[:] = sp.a_xy[:] = 0.0
        sp.v_h = sp.a_h = 0.0
        sp.R[:] = tool.R
        sp.omega[:] = sp.domega[:] = 0.0
        sp.contact, sp.force_n = False, 0.0
        self._turn = None

    def rest_at(self, tool: ToolState) -> None:
        """Setpoint = the measured pose (in contact: in the plane; the force stays), at rest."""
        self.aim.drop()
        sp = self.setpoint
        sp.xy[:] = tool.xy
        sp.v_xy[:] = sp.a_xy[:] = 0.0
        if not sp.contact:
            sp.h, sp.v_h, sp.a_h = tool.h, 0.0, 0.0
        sp.R[:] = tool.R
        sp.omega[:] = sp.domega[:] = 0.0
        self._turn = None

    def cancel_turn(self) -> None:
        self._turn = None

    def rest_in_plane(self) -> None:
        """Zero in-plane velocity and acceleration (the position stays)."""
        self.setpoint.v_xy[:] = self.setpoint.a_xy[:] = 0.0

    def adopt_board(self, old: BoardPose, new: BoardPose) -> None:
        """Re-express the setpoint on a moved board so that it stays where it is in the world."""
        sp = self.setpoint
        xyh = new.to_board(old.to_world(sp.xyh()))
        sp.xy[:], sp.h = xyh[:2], float(xyh[2])

    def fly_to_hover(self, xy_m: np.ndarray, board: BoardPose) -> bool:
        """Rest to rest to ``standoff_m`` above ``xy_m`` (2,) [m], turning the pad flat onto the board meanwhile; with
        :attr:`arm`, only as high as the elbow keeps :data:`HOVER_ELBOW_ROOM_RAD` from its limit and
        :data:`STRETCH_ROOM_RAD` from stretched (down to ``creep_height_m``): False when the hover was lowered so.
        Where no height is roomy, over a point nearby that is (:meth:`_hover`)."""
        sp = self.setpoint
        R_goal = tool_rotation_on_board(board.R)
        xy, h = self._hover(board, np.asarray(xy_m, float), min(self.p.creep_height_m, self.p.standoff_m), R_goal)
        mover = rest_to_rest(sp.xyh(), np.array([*xy, h]), self.p.approach_speed_m_s, 0.5)
        self._start(mover)
        self._force_over_s = 0.0
        T_turn = max(orientation_duration(sp.R, R_goal, self.p.turn_rate_rad_s), mover.T, 0.3)
        self._turn = OrientationBlend(sp.R, R_goal, T_turn)
        sp.contact = False
        return h >= self.p.standoff_m

    def _hover(self, board: BoardPose, xy: np.ndarray, lowest_h: float, R: np.ndarray) -> tuple[np.ndarray, float]:
        """The hover for a stain at ``xy`` (2,) [m] on ``board``, the pad turned ``R``: (xy, h [m]) at the highest
        roomy height (:meth:`_reachable_height`, :data:`HOVER_ELBOW_ROOM_RAD`); where none down to ``lowest_h`` is
        roomy, the first point along the board that has one, :data:`HOVER_SHIFT_STEP_M` at a time away from the
        shoulder (towards it when the elbow stretches), up to :data:`HOVER_SHIFT_MAX_M` and on the board (counted
        ``hovers_shifted``); none there: ``xy`` at ``lowest_h``."""
        h = self._reachable_height(board, xy, self.p.standoff_m, lowest_h, R, HOVER_ELBOW_ROOM_RAD)
        if self.arm is None or self.roomy(board, xy, h, R, HOVER_ELBOW_ROOM_RAD):
            return xy, h
        p = board.to_world(np.array([xy[0], xy[1], h]))
        away = board.R[:, :2].T @ (p + R @ self.arm.wrist_in_pad_m - self.arm.shoulder_m)
        n = float(np.linalg.norm(away))
        if n < 1e-9:
            return xy, h
        u = away / n if self.arm.elbow_rad(p, R) >= STRETCH_ROOM_RAD else -away / n
        for k in range(1, int(round(HOVER_SHIFT_MAX_M / HOVER_SHIFT_STEP_M)) + 1):
            there = np.clip(xy + k * HOVER_SHIFT_STEP_M * u, 0.0, board.size_m)
            h_there = self._reachable_height(board, there, self.p.standoff_m, lowest_h, R, HOVER_ELBOW_ROOM_RAD)
            if self.roomy(board, there, h_there, R, HOVER_ELBOW_ROOM_RAD):
                self.counters["hovers_shifted"] += 1
                return there, h_there
        return xy, h

    def met_board(self, force_n: float, dt_s: float) -> bool:
        """In a flight, the measured normal force ``force_n`` [N] this tick of ``dt_s`` [s]: True once it has stayed
        at or over ``contact_threshold_n`` for :data:`FLIGHT_TOUCH_S` (then :meth:`stop_where_touched`)."""
        self._force_over_s = self._force_over_s + dt_s if force_n >= self.f.contact_threshold_n else 0.0
        return self._force_over_s >= FLIGHT_TOUCH_S - 1e-9

    def stop_where_touched(self, tool: ToolState) -> None:
        """End a flight where the pad met the board: x, y, h the measured ones, at rest (a turn goes on), in the
        air until :meth:`press`. The reference comes back to the pad, which the board stopped off it."""
        self.aim.drop()
        self._mover, self._force_over_s = None, 0.0
        sp = self.setpoint
        sp.xy[:], sp.h = tool.xy, tool.h
        sp.v_xy[:] = sp.a_xy[:] = 0.0
        sp.v_h = sp.a_h = 0.0

    def turn_half_if_cramped(self) -> bool:
        """At rest over a stain, before the descent: turn the pad half about its normal (:mod:`arm.pad_turn`, A7 by pi
        towards the middle of its range, at ``turn_rate_rad_s``) when the measured :attr:`joints` stand near a limit
        and the turn gives them room; True when a turn started (counted ``pad_half_turns``)."""
        if self.joints is None or self.joint_limits is None:
            return False
        way = half_turn_way(self.joints, *self.joint_limits)
        if way == 0.0:
            return False
        sp = self.setpoint
        R_goal = half_turned(sp.R)
        self._turn = OrientationBlend(sp.R, R_goal, orientation_duration(sp.R, R_goal, self.p.turn_rate_rad_s, way),
                                      about_z=way)
        self.counters["pad_half_turns"] += 1
        return True

    def descend(self, first_touch: bool = False) -> None:
        """Down to ``creep_height_m`` (``first_touch``: the board's surface not touched yet, so only as far as
        perception's error allows: ``first_creep_height_m``), arriving at the creep speed (``descend_speed_m_s``
        downwards, no acceleration), at the approach speed's mean (air mode: to rest at ``air_height_m``)."""
        sp = self.setpoint
        if self.p.air:
            bottom = self.p.air_height_m
            T = max(abs(sp.h - bottom) / self.p.approach_speed_m_s, 0.3)
            self._start(vertical_move(sp.xy, sp.h, bottom, T))
            return
        bottom = min(self.p.first_creep_height_m if first_touch else self.p.creep_height_m, sp.h)
        T = max(abs(sp.h - bottom) / self.p.approach_speed_m_s, 0.2)
        self._start(vertical_move(sp.xy, sp.h, bottom, T, sp.v_h, -self.p.descend_speed_m_s))

    def creep(self) -> None:
        """On at ``descend_speed_m_s``, constant (the descent hands over at that speed), towards and past the
        surface, to ``contact_search_m`` below it; the contact is found at that speed wherever the board is
        within ``creep_height_m`` of where it was expected."""
        sp = self.setpoint
        bottom = -self.p.contact_search_m
        v = self.p.descend_speed_m_s
        T = max(sp.h - bottom, 1e-3) / v
        self._start(vertical_move(sp.xy, sp.h, bottom, T, -v, -v))

    def press(self, tool: ToolState) -> None:
        """In contact at the measured height: the force target ramps from the measured force to ``target_n``."""
        sp = self.setpoint
        sp.v_xy[:] = sp.a_xy[:] = 0.0
        sp.h, sp.v_h, sp.a_h = tool.h, 0.0, 0.0
        sp.contact = True
        sp.force_n = min(max(tool.force_n, 0.0), self.f.target_n)
        self._force.restart(sp.force_n, self.f.target_n, self.f.ramp_s)

    def press_measured(self, force_n: float) -> None:
        """In contact, pressing with ``force_n`` [N] (capped at the target), e.g. when found pressing."""
        self.setpoint.contact, self.setpoint.force_n = True, min(force_n, self.f.target_n)

    def stop_turn(self, duration_s: float) -> None:
        """Bring a running turn to rest smoothly within ``duration_s`` [s], where it is heading."""
        if self._turn is not None:
            self._turn.stop(duration_s)

    def brake(self, duration_s: float, force_ramp_s: float, bounds: tuple[float, float] | None = None,
              board: BoardPose | None = None) -> bool:
        """Bring the reference to rest C2-continuously: True in contact (in-plane, force to 0), False in the air.

        ``bounds`` (max acceleration [m/s^2], max jerk [m/s^3]): in contact, take longer than ``duration_s`` if
        the in-plane stop needs it to stay within them (a retreat; a stop for safety keeps its duration); with
        ``board`` and :attr:`arm`, never so long that the pad coasts off the board or to where the elbow is
        stretched (:meth:`roomy`).

        In the air, x, y and h stop within :data:`AIR_BRAKE_S`, never below
        the current height (a brake while descending must not carry the pad
        on into the board).
        """
        sp = self.setpoint
        if sp.contact:
            reachable = None
            if board is not None and self.arm is not None:
                def reachable(xy: np.ndarray) -> bool:
                    return bool(np.all(xy >= 0.0) and np.all(xy <= board.size_m)) and self.roomy(board, xy, sp.h)
            self._xy_brake = (brake_to_rest(sp.xy, sp.v_xy, sp.a_xy, duration_s) if bounds is None else
                              bounded_brake_to_rest(sp.xy, sp.v_xy, sp.a_xy, duration_s, *bounds,
                                                    reachable=reachable))
            self._force.restart(sp.force_n, 0.0, force_ramp_s)
            return True
        self._start(brake_above(sp.xyh(), np.array([*sp.v_xy, sp.v_h]), np.array([*sp.a_xy, sp.a_h]),
                                  min(duration_s, AIR_BRAKE_S)))
        return False

    def lift(self, tool: ToolState, from_measured: bool = False, board: BoardPose | None = None) -> bool:
        """Out of contact (from the measured height) or on from the air, up to ``standoff_m``; ``from_measured``:
        ``standoff_m`` above the measured height (a pad found pressing while the board model says it is in the
        air: the model is off, so the lift goes by what is measured). With ``board`` and :attr:`arm`, only as
        high as the elbow keeps :data:`STRETCH_ROOM_RAD` from stretched straight (at least :data:`MIN_LIFT_M`):
        returns False when the lift was cut short so."""
        sp = self.setpoint
        h0 = tool.h if sp.contact or from_measured else sp.h
        v0 = 0.0 if sp.contact or from_measured else sp.v_h
        sp.contact, sp.force_n = False, 0.0
        goal_h = h0 + self.p.standoff_m if from_measured else max(self.p.standoff_m, h0)
        reach_h = self._reachable_height(board, sp.xy, goal_h, min(h0 + MIN_LIFT_M, goal_h))
        full = reach_h >= goal_h
        goal_h = reach_h
        T = max(abs(goal_h - h0) / self.p.lift_speed_m_s, 0.3)
        self._start(vertical_move(sp.xy, h0, goal_h, T, v0))
        sp.h, sp.v_h, sp.a_h = h0, v0, 0.0
        return full

    def roomy(self, board: BoardPose, xy: np.ndarray, h: float, R: np.ndarray | None = None,
              limit_room_rad: float = 0.0) -> bool:
        """The pad at ``(xy, h)`` on ``board`` (2,) [m], turned ``R`` (3, 3; default: as the setpoint is), leaves the
        elbow :data:`STRETCH_ROOM_RAD` from stretched straight and ``limit_room_rad`` [rad] within its limit (True
        without :attr:`arm`)."""
        if self.arm is None:
            return True
        p, R = board.to_world(np.array([xy[0], xy[1], h])), self.setpoint.R if R is None else R
        return self.arm.elbow_rad(p, R) >= STRETCH_ROOM_RAD and self.arm.elbow_room_rad(p, R) >= limit_room_rad

    def reach_problem(self, board: BoardPose, xy: np.ndarray) -> str | None:
        """Why the pad, flat on ``board`` at ``xy`` (2,) [m], is beyond the arm (:func:`arm.reach.pad_reach_problem`;
        None: it is not, or no :attr:`arm`)."""
        if self.arm is None:
            return None
        return pad_reach_problem(self.arm, board.to_world(np.array([xy[0], xy[1], 0.0])),
                                 tool_rotation_on_board(board.R))

    def stain_reach_problem(self, board: BoardPose, stain: Stain) -> str | None:
        """Why the arm cannot wipe ``stain`` whole (None: it can, or no :attr:`arm`): its centre or one of its ends
        (half its size either way along its main axis, half its width across; round when the width is not known),
        where the wiping pad's centre goes, is beyond the arm (:meth:`reach_problem`). A stain whose far end lies
        where the elbow stretches straight would be wiped through the arm's singular pose."""
        why = self.reach_problem(board, stain.centre_m)
        if why is not None or self.arm is None:
            return why
        u = np.array([np.cos(stain.axis_rad), np.sin(stain.axis_rad)])
        v = np.array([-u[1], u[0]])
        half_w = 0.5 * (stain.width_m if stain.width_m > 0.0 else stain.size_m)
        for name, d in (("end", 0.5 * stain.size_m * u), ("end", -0.5 * stain.size_m * u), ("side", half_w * v),
                        ("side", -half_w * v)):
            xy = stain.centre_m + d
            why = self.reach_problem(board, xy)
            if why is not None:
                return f"its {name} at ({xy[0]:.2f}, {xy[1]:.2f}) m is {why}"
        return None

    def _reachable_height(self, board: BoardPose | None, xy: np.ndarray, goal_h: float, lowest_h: float,
                          R: np.ndarray | None = None, limit_room_rad: float = 0.0) -> float:
        """The highest height [m] up to ``goal_h`` above ``xy`` (2,) [m] that is :meth:`roomy` (``R``,
        ``limit_room_rad``), scanned down in 5 mm steps to ``lowest_h``; ``goal_h`` without the arm or the board."""
        if self.arm is None or board is None:
            return goal_h
        h = goal_h
        while h > lowest_h:
            if self.roomy(board, xy, h, R, limit_room_rad):
                return h
            h -= 0.005
        return lowest_h

    def fly_to_survey(self, board: BoardPose) -> None:
        """To ``standoff_m`` above the look point of the whole board (:func:`~.look_points.survey_point`), turning
        the pad flat; the point is chosen off the tick (:attr:`aim`), the setpoint holding meanwhile."""
        arm, clearance_m, h = self.arm, self.p.look_clearance_m, self.p.standoff_m
        self._mover = None
        self.aim.start(lambda: survey_point(board, clearance_m, arm, h), lambda xy: self.fly_to_hover(xy, board))

    def fly_to_survey_again(self, board: BoardPose) -> None:
        """At the current height to :func:`~.look_points.resurvey_point` off the survey point the pad waits over
        (chosen off the tick, :attr:`aim`); no point that sees more of what the first hid: :attr:`stayed`."""
        arm, first, h = self.arm, self.setpoint.xy.copy(), self.setpoint.h
        self._mover, self.stayed = None, False
        self.aim.start(lambda: resurvey_point(board, first, arm, h), self._fly_to_survey_again_point)

    def _fly_to_survey_again_point(self, goal: np.ndarray | None) -> None:
        if goal is None:
            self.stayed = True
            return
        self._fly_to_look_point(goal)

    def fly_to_look(self, board: BoardPose, pending: list[Stain], attempt: int = 0) -> bool:
        """At the current height to :func:`look_point` off the ``pending`` stains; False (no move) if already there
        and known at once (without :attr:`aim`'s executor; off the tick, a look whose point is where the pad is
        arrives at once with :attr:`stayed`).

        The arm reaches back towards the robot base, away from them, so the
        camera sees them; ``look_clearance_m`` beyond their edge. ``attempt``: looks made at them before
        (each from another point).
        """
        centres, sizes = [np.array(s.centre_m, float) for s in pending], [float(s.size_m) for s in pending]  # copies
        arm, clearance_m, h = self.arm, self.p.look_clearance_m, self.setpoint.h
        self._mover, self.stayed = None, False
        self.aim.start(lambda: look_point(board, centres, sizes, clearance_m, arm, h, attempt,
                                          stain_targets(centres, sizes)), self._fly_to_look_point)
        return self.aim.busy or not self.stayed

    def _fly_to_look_point(self, goal: np.ndarray) -> None:
        sp = self.setpoint
        if np.linalg.norm(goal - sp.xy) < 0.005:
            self.stayed = True
            return
        self._start(rest_to_rest(sp.xyh(), np.array([*goal, sp.h]), self.p.approach_speed_m_s, 0.5))

    def _start(self, mover: Quintic) -> None:
        """``mover`` moves x, y, h from now on; a look point still being chosen is of no use any more."""
        self.aim.drop()
        self.stayed = False
        self._mover = mover

    # ------------------------------------------------------------------ one tick
    def step_turn(self, dt_s: float) -> None:
        """Advance the pad's turn, if one runs, by ``dt_s`` [s]."""
        if self._turn is None:
            return
        sp, turn = self.setpoint, self._turn
        turn.update(dt_s)
        sp.R[:], sp.omega[:], sp.domega[:] = turn.R, turn.omega, turn.domega
        if turn.finished:
            self._turn = None
            sp.omega[:] = 0.0
            sp.domega[:] = 0.0

    def move(self, dt_s: float) -> bool:
        """Advance x, y, h along the quintic by ``dt_s`` [s]; True once at its end. While :attr:`aim` chooses where
        to fly, False (the setpoint holds); a look that :attr:`stayed`, True."""
        if not self.aim.poll():
            return False
        m, sp = self._mover, self.setpoint
        if m is None and self.stayed:
            return True
        assert m is not None, "move() before a move was started"
        m.update(dt_s)
        sp.xy[:] = m.position[:2]
        sp.v_xy[:] = m.velocity[:2]
        sp.a_xy[:] = m.acceleration[:2]
        sp.h, sp.v_h, sp.a_h = float(m.position[2]), float(m.velocity[2]), float(m.acceleration[2])
        return m.finished

    def ramp_force(self, dt_s: float) -> bool:
        """Advance the force target along its ramp by ``dt_s`` [s]; True once at the ramp's goal."""
        self.setpoint.force_n = self._force.update(dt_s)
        return self._force.finished

    def unpress(self, dt_s: float) -> bool:
        """Advance the in-plane brake and the force ramp by ``dt_s`` [s]; True once both are done."""
        b, sp = self._xy_brake, self.setpoint
        assert b is not None, "unpress() before a press ended"
        b.update(dt_s)
        sp.xy[:], sp.v_xy[:], sp.a_xy[:] = b.position, b.velocity, b.acceleration
        return self.ramp_force(dt_s) and b.finished
