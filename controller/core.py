"""One control tick, without I/O: measured joints in, joint torques out.

:class:`ControllerCore` ties the skill executor (board-frame setpoints), the normal force regulator, the Cartesian
impedance law and the torque shaping together. The service (:mod:`controller.service`) feeds it robot states on its
clock; tests and benchmarks can call it directly against an in-process simulator.

Per tick:

1. pad pose and twist from Pinocchio; in the board frame: (x, y, h), in-plane speed, normal force from the measured
   contact wrench;
2. watches (executor fault, lift off): filtered force above the cap; a joint torque neither the last applied command
   nor the measured contact explains (:class:`~controller.control.watch.DisturbanceWatch`); contact lost while
   pressing;
3. executor setpoint -> world reference (position, orientation, twist, acceleration); in contact the normal is
   force-regulated (PI + feed-forward);
4. impedance torque with the pose error clipped, the stiffness ramped in after (re)starts, a brake above the
   Cartesian speed limit, plus a repulsion near joint limits, a brake on joints above their share of the speed
   limit; then absolute and rate torque limits (the model gravity, when the robot lacks its own, is outside the rate
   limit).
"""

from __future__ import annotations

import time

import numpy as np

from arm.reach import arm_reach
from arm.robot_model import RobotModel
from interfaces.messages import Phase
from lampskit.core.skill import Skill

from .arm_model import ArmModel
from .control.demand_kernels import joint_demand_into, largest_share
from .control.force import NormalForceRegulator
from .control.impedance import (
    ImpedanceTerms,
    Kinematics,
    Reference,
    TaskShaping,
    impedance_torque,
    task_modes,
    task_stiffness,
)
from .control.kernels import reference_into, tool_in_board, trace_row
from .control.limit_kernels import clearance_into, limit_torque, normal_neutral_into, self_motion_limit_into
from .control.limits import SpeedOverride, TorqueShaper, limits_from_settings, speed_excess_force
from .control.params import mode_frequency_cap
from .control.watch import ContactWatch, DisturbanceWatch
from .core_state import ModesCache, TickBuffers, TickClock, TickMemory
from .executor import SkillExecutor
from .executor_types import BoardPose, Setpoint, ToolState
from .params import ControllerParams
from .rest_posture import rest_posture_for
from .tick_io import LastCommand, TickInput, TickOutput, TickStatus, conclude
from .trace import PHASE_CODES, TRACE_COLUMNS, Trace  # noqa: F401 (the trace's names, exported here too)

#: The skill's clock advances at most this many robot periods in one tick (a longer gap between states: our own
#: processes stalled while the robot repeated or held the last command; the reference must not leap ahead).
SKILL_STEP_CAP_PERIODS = 2.0
_HALTED = (Phase.FAULT, Phase.ESTOP)
#: The task's modes (an eigen-decomposition of Lambda on K) are refreshed this often [ticks] and whenever the
#: stiffness scale changes: Lambda changes slowly with the pose, and the decomposition costs a fifth of a tick.
MODES_EVERY_TICKS = 10
#: How far ahead [s] the speed override looks along the reference's acceleration (a transition speeds up fast).
OVERRIDE_LOOKAHEAD_S = 0.1


class ControllerCore:
    """The controller's per-tick computation. See the module docstring.

    Its parts: the skill ``executor``, the ``force`` regulator, the torque ``shaper``, the speed ``override``,
    the watches (``disturbance``, ``contact_watch``), the ``arm`` it learns, the law's inputs (``kin``,
    ``ref``, ``shaping``) and what it keeps between ticks, grouped (:mod:`controller.core_state`): ``buf``
    (the preallocated arrays), ``clock``, ``modes``, ``mem``; the properties below read the figures others
    report (the status, tests).
    """

    def __init__(self, params: ControllerParams, skill: Skill, model: RobotModel | None = None) -> None:
        self.p = params
        self.model = model or RobotModel()
        self.executor = SkillExecutor(skill, params.executor, params.force, params.planner)
        (motion := self.executor.motion).arm = arm_reach(self.model)  # look points where the elbow has room
        f = params.force
        self.force = NormalForceRegulator(f.kp, f.ki, f.integral_limit_n, f.cap_n, f.filter_s)
        lim = self.model.limits
        self.shaper = TorqueShaper(lim.tau_max, params.limits.torque_rate_nm_per_ms * 1000.0)
        self.ref = Reference()
        self.shaping = TaskShaping(normal_damping_1_s=f.normal_damping_1_s, n_joints=self.model.nq,
                                   max_position_error_m=params.limits.max_position_error_m,
                                   max_rotation_error_rad=params.limits.max_rotation_error_rad)
        # published in batches with each status: a ring of >= 5 s covers a late status
        n_trace = max(params.trace_ticks, int(5 * params.rate_hz) if params.publish_trace else 0)
        self.trace = Trace(n_trace) if n_trace else None
        self.override = SpeedOverride(self.model.limits.dq_max, params.limits.reference_joint_speed_share,
                                      jerk_bound_m_s3=params.planner.max_jerk_m_s3)
        self.kin = Kinematics(self.model)
        # the clearance posture (controller.control.limits.clearance_torque), into the shaping's nullspace torques
        self.buf = TickBuffers(self.kin, limits_from_settings(self.model.limits, params.limits))
        motion.joints, motion.joint_limits = self.buf.q, (lim.q_min, lim.q_max)  # the pad's half turn looks at them
        if params.limits.clearance_stiffness_nm_rad > 0.0:  # the clearance is written into the shaping's record
            self.buf.clearance = self.shaping.posture_in_record(self.buf.clearance)
        self.clock = TickClock(params.rate_hz)
        self.modes = ModesCache(params.impedance.max_mode_frequency_rad_s)
        self.mem = TickMemory()
        self.posture = rest_posture_for(self.model, params.limits)  # the rest pose, planned off the tick
        watch = params.limits
        self.disturbance = DisturbanceWatch(watch.disturbance_share * lim.tau_max, watch.disturbance_filter_s,
                                            watch.disturbance_persist_s)
        self.contact_watch = ContactWatch(f.contact_threshold_n, f.contact_loss_s)
        self.arm = ArmModel(params.model, self.model, f.contact_threshold_n)  # the load and model error learned
        self._compile_law()

    @property
    def time_s(self) -> float:
        """The robot time the ticks covered [s]."""
        return self.clock.time_s

    @property
    def robot_rate_hz(self) -> float:
        """The robot's declared state rate [Hz], 0 until a state said it."""
        return self.clock.robot_rate_hz

    @property
    def skill_steps_capped(self) -> int:
        """Ticks whose skill step was cut to :data:`SKILL_STEP_CAP_PERIODS` robot periods."""
        return self.clock.skill_steps_capped

    @property
    def mode_cap_rad_s(self) -> float:
        """The cap on the task modes' frequency [rad/s] for the robot's rate."""
        return self.modes.cap_rad_s

    @property
    def q_rest(self) -> np.ndarray | None:
        """(n,) [rad] the posture's rest pose (the first state's, moving to the plan), None before."""
        return self.posture.q

    @property
    def normal_force_n(self) -> float:
        """Last measured normal force [N] (0 before a board is known)."""
        return self.mem.normal_force_n

    @property
    def press_n(self) -> float:
        """The press force last commanded [N] (0 out of contact)."""
        return self.mem.press_n

    @property
    def override_used(self) -> float:
        """The time scale the last skill step used."""
        return self.mem.override_used

    @property
    def last_terms(self) -> ImpedanceTerms | None:
        """The law's terms of the last tick (None before one)."""
        return self.mem.last_terms

    def _compile_law(self) -> None:
        """Compile the law's kernels for the argument types the tick passes them (or load them from numba's
        cache): the first tick must not wait a second or more for the compiler. Leaves no state behind."""
        lim = self.model.limits
        q = self.buf.q
        q[:] = 0.5 * (lim.q_min + lim.q_max)
        kin = self.kin.update(q, self.buf.dq)
        imp = self.p.impedance
        modes = task_modes(kin.Lambda, task_stiffness(imp), imp.damping_factor, self.modes.cap_rad_s,
                           self.modes.out)
        shaping = TaskShaping(force_axis=np.eye(3)[:, 2], extra_force_n=np.zeros(3), posture_nm=self.buf.clearance,
                              n_joints=self.model.nq)
        buf = self.buf
        clearance_into(q, buf.dq, buf.limits, buf.clearance)
        self_motion_limit_into(buf.clearance, buf.dq, kin.M, kin.M_inv, kin.J, kin.Lambda, buf.limits)
        impedance_torque(self.model, q, buf.dq, Reference(), imp, q, True, shaping, kin, modes, buf.terms)
        axis = shaping.force_axis
        assert axis is not None  # set above: the same view type as the tick's
        normal_neutral_into(q, buf.dq, kin.rec, buf.limits, axis, buf.neutral)
        limit_torque(buf.tau, q, buf.dq, kin.M, kin.g, True, buf.limits, self.shaper.rec.copy(), 1.0)
        buf.tau[:] = 0.0
        sp = Setpoint()
        reference_into(self.buf.board, (sp.xy, sp.v_xy, sp.a_xy, sp.R, sp.omega, sp.domega), (0.0, 0.0, 0.0), 1.0,
                       self.ref.rec)
        joint_demand_into(kin.M_inv, kin.J, kin.Lambda, self.ref.twist, self.ref.accel, 1.0, OVERRIDE_LOOKAHEAD_S,
                          self.buf.demand, self.buf.demand_work)
        self.disturbance.compile(kin)
        largest_share(self.buf.demand, self.override.inv_dq_max)
        tool_in_board(self.buf.board, kin.rec, self.buf.wrench, self.buf.xyh, self.buf.v_board)
        if self.trace is not None:
            row = self.trace.data[0]
            trace_row(row, (0.0, 0.0, 1.0), (True, sp.xy, sp.v_xy, sp.a_xy, 0.0), self.buf.xyh, self.ref.p_m, kin.p,
                      (0.0, 0.0))
            row[:] = 0.0
        self.ref.p_m[:] = 0.0
        self.ref.R[:] = np.eye(3)
        self.arm.compile(kin)

    def restart(self) -> None:
        """The robot came back after a loss: hold where it is, ramp the gains in again, re-approach."""
        self.mem.hold = None
        self.posture.reset()
        self.clock.since_start_s = 0.0
        self.force.reset()
        self.override.reset()
        self.disturbance.reset()
        self.mem.applied_known = False
        self.mem.xy_prev = None
        self.executor.restart()

    def tick(self, inp: TickInput, out: TickOutput) -> TickStatus:
        """One tick: the torques answering the state in ``inp`` into ``out`` (:mod:`controller.tick_io`); the status.

        After ``LastCommand.HELD`` the skill's clock runs only as far as the arm went along the path
        (:meth:`_held_step`: an arm whose reference ran on while braked would leap to catch up once released and
        bounce off the board), the speed override drops to that pace and climbs back once commands apply again
        (:meth:`SpeedOverride.held`), the force integral stands, the rate limit counts from the torques last
        applied, and the contact-loss watch counts again (a contact lost meanwhile is not ours)."""
        t0 = time.perf_counter_ns()
        applied = inp.applied_nm if inp.last == LastCommand.APPLIED else None
        running = inp.running_nm if applied is None and inp.running_known else None
        tau = self._control(inp.q_rad, inp.dq_rad_s, inp.wrench, inp.gravity_compensated, inp.dt_s, inp.tau_max_nm,
                            applied, inp.last == LastCommand.HELD, running)
        status = conclude(out, tau, self.executor.phase in _HALTED, t0)
        if status == TickStatus.NON_FINITE:
            self.shaper.reset(None)
            self.executor.fault("the control law gave non-finite torques (absurd robot state?)")
        return status

    def _control(self, q: np.ndarray, dq: np.ndarray, wrench: np.ndarray, gravity_compensated: bool, dt_s: float,
                 tau_max_nm: np.ndarray | None, applied_nm: np.ndarray | None, robot_held: bool,
                 running_nm: np.ndarray | None) -> np.ndarray:
        """:meth:`tick`'s torques (n,) [Nm] (an internal buffer), its record unpacked (None: not known)."""
        self.clock.time_s += dt_s
        self.buf.q[:] = q  # the compiled law sees the same array types every tick (no recompilation)
        self.buf.dq[:] = dq
        self.buf.wrench[:] = wrench
        q, dq, wrench = self.buf.q, self.buf.dq, self.buf.wrench
        if self.posture.q is None:
            self.posture.begin(q)
            self.shaper.reset(None)
        self.posture.step(q, dt_s)
        if tau_max_nm is not None:
            np.minimum(self.model.limits.tau_max, tau_max_nm, out=self.shaper.tau_max)
        kin = self.kin.update(q, dq)
        self.arm.correction.apply(kin)  # the model's static torque, corrected
        self._watch_disturbance(kin, dq, wrench, gravity_compensated, dt_s, applied_nm)
        known = applied_nm if applied_nm is not None else running_nm
        if known is not None:
            self.buf.last_applied[:] = known
            self.mem.applied_known = True
        if robot_held:
            self.contact_watch.lost_s = 0.0
            self._rate_from_applied(kin, gravity_compensated)
        board = self.executor.board
        identifying = self.arm.identifying(board is not None)
        if board is None or identifying:
            self._hold_reference(kin)
            if identifying:  # the pad rolls about its normal, for the load estimate
                ref, hold = self.ref, self.mem.hold
                assert hold is not None, "the reference held without a pose"  # _hold_reference set it
                self.arm.identify_reference(hold[1], dt_s, ref.R, ref.twist, ref.accel)
            sp = None
        else:
            n = board.normal
            tool = self._measure_tool(board, n, kin, wrench, dt_s)
            # a held cycle's clock runs only as far as the arm went along the path (braked: it stands; coasting on
            # the stack's last message: it keeps pace) and the override drops to that pace; the force integral
            # stands
            if robot_held:
                step = self._held_step(tool, dt_s)
                scale = step / dt_s if dt_s > 0 else 0.0
                self.override.held(scale)  # released, the skill speeds up again from the pace the arm kept
            else:
                scale = self.override.scale
                step = self._skill_step(dt_s) * scale
            self.mem.override_used = scale
            sp = self.executor.step(step, tool)
            if sp.contact:
                self.arm.first_contact()
            self.buf.sp_v_xy[:] = sp.v_xy
            self._reference_from_setpoint(board, n, sp, tool, scale)
            self._regulate_force(n, sp, 0.0 if robot_held else dt_s)
            if not robot_held:
                self._update_override(kin, sp, scale, dt_s)
            if self.mem.xy_prev is None:
                self.mem.xy_prev = np.zeros(2)
            self.mem.xy_prev[:] = tool.xy
        self._shape_task(kin, dt_s)
        tau = self._torque(q, dq, kin, gravity_compensated, dt_s)
        if self.trace is not None:
            self._record(sp, kin.p)
        return tau

    def _watch_disturbance(self, kin: Kinematics, dq: np.ndarray, wrench: np.ndarray, gravity_compensated: bool,
                           dt_s: float, applied_nm: np.ndarray | None) -> None:
        """Fault when the arm moves in a way the applied command and the measured contact do not explain."""
        watch = self.disturbance
        if applied_nm is None:
            watch.skip(dq)
            return
        applied = self.buf.applied
        applied[:] = applied_nm
        if gravity_compensated:  # the robot adds its own gravity, not the model correction (which is in kin.g)
            applied += kin.g
            applied -= self.arm.correction.c
        tripped = watch.update(kin.M, kin.nle, kin.J, dq, applied, wrench, dt_s)
        self.arm.after_watch(watch.tau_d, kin, dq, wrench, dt_s, self.executor.phase)
        if tripped:
            j = watch.worst_joint()
            self.executor.fault(f"unexplained joint torque: A{j + 1} {watch.tau_d[j]:+.1f} Nm (limit "
                                f"{watch.limit[j]:.0f} Nm for {watch.persist_s * 1000:.0f} ms): the arm is not "
                                "moving as commanded (another controller's torques? a collision the force sensor "
                                "does not see?)", at_the_arm=True)
            watch.reset()

    def _held_step(self, tool: ToolState, dt_s: float) -> float:
        """The skill's step [s] over a held cycle: the time the reference needs at its last setpoint velocity to
        cover the pad's in-plane progress along it since the last tick, within ``[0, dt_s x the override]`` (the
        override before the hold began).

        A robot that held did not run our command: braked (the sim, a robot server) it stands, and so does the
        reference; on the lbr stack it re-applies its last message, whose position target keeps the stack's PID
        walking at nearly the arm's last speed, so the arm coasts on. A reference standing still there fell 13 mm
        behind the pad over a 42 ms gap in a real-time lbr-sim run, and pulling the pad back from its run-out
        pressed its edge into the board at 77 N.
        """
        xy, prev = tool.xy, self.mem.xy_prev
        v = self.buf.sp_v_xy
        vv = float(v @ v)
        if prev is None or vv < 1e-8:
            return 0.0
        progress = float((xy[0] - prev[0]) * v[0] + (xy[1] - prev[1]) * v[1]) / vv
        return min(max(progress, 0.0), dt_s * max(self.override.scale, self.override.resume_to))

    def _rate_from_applied(self, kin: Kinematics, gravity_compensated: bool) -> None:
        """Over a held cycle the rate limit counts from the torques the robot last applied, not from our answers.

        Those answers reached nothing (the robot braked, or re-applied its last message: the lbr stack does,
        lbr_torque_command_controller.cpp:42-55); counted from them, 18 held cycles let the answers walk 18 Nm
        away at 1 Nm a cycle, and the first message that arrived stepped the robot by all of it at once (a
        real-time lbr-sim run: the pad bounced off the board and came back at 79 N). Counted from the applied
        torques, the first command after a hold is within one rate step of what the robot was applying.
        """
        if not self.mem.applied_known:
            return
        prev = self.shaper.prev
        prev[:] = self.buf.last_applied
        if not gravity_compensated:  # the rate limit leaves gravity out (``limit_torque``), the answers carry it
            prev -= kin.g

    def _hold_reference(self, kin: Kinematics) -> None:
        """No board yet: the executor waits and the reference holds the pose of the first such tick."""
        self.executor.wait()
        if self.mem.hold is None:
            self.mem.hold = (kin.p.copy(), kin.R.copy())
        ref = self.ref
        ref.p_m[:], ref.R[:] = self.mem.hold
        ref.twist[:] = 0.0
        ref.accel[:] = 0.0
        self.shaping.force_axis = None
        self.mem.normal_force_n = 0.0

    def _measure_tool(self, board: BoardPose, n: np.ndarray, kin: Kinematics, wrench: np.ndarray,
                      dt_s: float) -> ToolState:
        """The pad in the board frame, the force along the normal ``n`` (3,) (filtered; over the cap: a fault)."""
        self._use_board(board)
        xyh, vb = self.buf.xyh, self.buf.v_board
        self.mem.normal_force_n = tool_in_board(self.buf.board, kin.rec, wrench, xyh, vb)
        self.force.measure(self.mem.normal_force_n, dt_s)
        ex = self.executor
        if self.force.over_cap and ex.phase not in _HALTED:
            ex.fault(f"normal force {self.force.filtered_n:.1f} N above the cap {self.p.force.cap_n:.0f} N")
        # views of the controller's buffers: the executor copies what it keeps
        return ToolState(xyh[:2], float(xyh[2]), vb[:2], float(vb[2]), kin.R, self.mem.normal_force_n)

    def _use_board(self, board: BoardPose) -> None:
        """Copy a new board's pose into the controller's own arrays (the kernels always see the same types)."""
        if board is not self.mem.board:
            self.mem.board = board
            self.buf.board_R[:] = board.R
            self.buf.board_origin[:] = board.origin_m

    def _reference_from_setpoint(self, board: BoardPose, n: np.ndarray, sp: Setpoint, tool: ToolState,
                                 scale: float) -> None:
        """The world reference of the board-frame setpoint, its rates at the time ``scale`` (velocities x scale,
        accelerations x scale^2); in contact, the measured height and no normal motion. One compiled call."""
        ref = self.ref
        c = sp.contact
        normal = (float(tool.h), 0.0, 0.0) if c else (float(sp.h), float(sp.v_h), float(sp.a_h))
        reference_into(self.buf.board, (sp.xy, sp.v_xy, sp.a_xy, sp.R, sp.omega, sp.domega), normal, float(scale),
                       ref.rec)

    def _update_override(self, kin: Kinematics, sp: Setpoint, scale: float, dt_s: float) -> None:
        """The time scale of the next tick from the joint speeds the unscaled reference asks for (the least-inertia
        ones, ``M^-1 J^T Lambda v``), looking ``OVERRIDE_LOOKAHEAD_S`` ahead along its acceleration; its changes
        within the planner's jerk bound on the executed in-plane reference (the setpoint's unscaled acceleration)."""
        ref = self.ref
        joint_demand_into(kin.M_inv, kin.J, kin.Lambda, ref.twist, ref.accel, float(scale), OVERRIDE_LOOKAHEAD_S,
                          self.buf.demand, self.buf.demand_work)
        self.override.update(self.buf.demand, dt_s, sp.a_xy)

    def _regulate_force(self, n: np.ndarray, sp: Setpoint, dt_s: float) -> None:
        """In contact, the press force along the normal ``n`` (3,) from the regulator (PI + feed-forward); else none."""
        shaping = self.shaping
        if sp.contact:
            shaping.force_axis = n
            in_contact = self.mem.normal_force_n > self.p.force.contact_threshold_n
            self.mem.press_n = self.force.command(sp.force_n, self.mem.normal_force_n, dt_s, in_contact)
            shaping.press_n = self.mem.press_n
            if self.contact_watch.update(sp.force_n, self.mem.normal_force_n, dt_s):
                self.contact_watch.lost_s = 0.0
                ex = self.executor
                where = f" in {ex.current_mp}" + (f" at stain {ex.stain_id}" if ex.stain_id >= 0 else "")
                self.executor.fault(f"contact lost{where}: {self.mem.normal_force_n:.1f} N measured for "
                                    f"{self.contact_watch.persist_s * 1000:.0f} ms while pressing "
                                    f"{sp.force_n:.1f} N (board gone? pad off? force sensor?)")
        else:
            shaping.force_axis = None
            self.mem.press_n = 0.0
            self.force.reset()
            self.contact_watch.lost_s = 0.0

    def _shape_task(self, kin: Kinematics, dt_s: float) -> None:
        """Stiffness ramped in (smoothstep from 20 %) since the (re)start; a brake above the speed limit."""
        self.clock.since_start_s += dt_s
        ramp = self.p.limits.gain_ramp_s
        s = 1.0 if ramp <= 0 else min(self.clock.since_start_s / ramp, 1.0)
        self.shaping.stiffness_scale = 0.2 + 0.8 * s * s * (3.0 - 2.0 * s)
        lim = self.p.limits
        self.shaping.extra_force_n = speed_excess_force(kin.twist, lim.max_speed_m_s, lim.speed_brake_gain_n_s_m,
                                                        self.buf.extra_force)

    def _torque(self, q: np.ndarray, dq: np.ndarray, kin: Kinematics, gravity_compensated: bool,
                dt_s: float) -> np.ndarray:
        """Impedance torque plus the joint-limit repulsion and the joint-speed brake (pressing on a board: less
        their force along its normal), then the rate and absolute limits (gravity outside the rate limit): two or
        three compiled calls, no allocation."""
        model = self.model
        if self.shaping.posture_nm is not None:
            clearance_into(q, dq, self.buf.limits, self.buf.clearance)
            self_motion_limit_into(self.buf.clearance, dq, kin.M, kin.M_inv, kin.J, kin.Lambda, self.buf.limits)
        q_rest = self.posture.q
        assert q_rest is not None, "a torque before the first state set the rest posture"
        terms = impedance_torque(model, q, dq, self.ref, self.p.impedance, q_rest, not gravity_compensated,
                                 self.shaping, kin, self._task_modes(kin), self.buf.terms)
        self.mem.last_terms = terms
        tau = self.buf.tau
        tau[:] = terms.tau_nm
        if gravity_compensated:  # the robot adds its own gravity and load data; the correction is ours to send
            tau += self.arm.correction.c
        # the robot steps from one command to the next within one of its cycles, however long the controller
        # took: the rate limit is per answer (at most one nominal period's worth), not per elapsed time
        axis = self.shaping.force_axis
        if axis is not None:  # pressing on a board: the limits' joint torques leave the press to the regulator
            normal_neutral_into(q, dq, kin.rec, self.buf.limits, axis, self.buf.neutral)
            tau += self.buf.neutral
        shaper = self.shaper
        hit = limit_torque(tau, q, dq, kin.M, kin.g, not gravity_compensated, self.buf.limits, shaper.rec,
                           shaper.rate * min(dt_s, self.clock.period_s))
        shaper.count(hit)
        return tau

    def _skill_step(self, dt_s: float) -> float:
        """The skill's step for a tick ``dt_s`` [s] after the last: at most :data:`SKILL_STEP_CAP_PERIODS` robot
        periods (the controller's own before a state has said the robot's rate). Over a longer gap our processes
        stood still while the robot repeated or held an old command; the arm did not follow the reference, so,
        as over a held cycle, the skill's clock does not run on (in one step it would also leap: the executed
        reference's acceleration jumped there, 1.4 km/s^3 of jerk after a 36 ms stall)."""
        period = 1.0 / self.clock.robot_rate_hz if self.clock.robot_rate_hz > 0 else self.clock.period_s
        cap = SKILL_STEP_CAP_PERIODS * period
        if dt_s > cap:
            self.clock.skill_steps_capped += 1
            return cap
        return dt_s

    def follow_robot_rate(self, rate_hz: float) -> None:
        """The robot sends states at ``rate_hz`` (its declared capability): cap the task modes for that loop
        delay (:func:`~controller.control.params.mode_frequency_cap`); the modes are recomputed at once."""
        if rate_hz == self.clock.robot_rate_hz:
            return
        self.clock.robot_rate_hz = rate_hz
        self.modes.cap_rad_s = mode_frequency_cap(self.p.impedance.max_mode_frequency_rad_s, rate_hz)
        self.modes.current = None

    def _task_modes(self, kin: Kinematics):
        scale = self.shaping.stiffness_scale
        self.modes.age += 1
        if self.modes.current is None or self.modes.age >= MODES_EVERY_TICKS or scale != self.modes.scale:
            imp = self.p.impedance
            self.modes.current = task_modes(kin.Lambda, task_stiffness(imp, scale), imp.damping_factor,
                                     self.modes.cap_rad_s, self.modes.out)
            self.modes.age, self.modes.scale = 0, scale
        return self.modes.current

    def _record(self, sp: Setpoint | None, p: np.ndarray) -> None:
        has_sp = sp is not None
        sp = sp or self.buf.no_setpoint
        clock = (self.clock.time_s, float(PHASE_CODES.get(self.executor.phase, -1)), float(self.mem.override_used))
        assert self.trace is not None, "a tick recorded without a trace"
        trace_row(self.trace.row(), clock, (has_sp, sp.xy, sp.v_xy, sp.a_xy, float(sp.contact)), self.buf.xyh,
                  self.ref.p_m, p, (float(self.mem.normal_force_n), float(self.mem.press_n)))
