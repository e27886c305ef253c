"""The KUKA LBR iiwa through lbr_fri_ros2_stack, as a clocked :class:`~robot.port.RobotPort`.

Built against the stack as its code behaves (lbr_fri_ros2_stack ``rolling``
218d723 and ``humble`` cca24ae; docs/real-robot.md has the table):

States: the stack's ``LBRState`` (zenoh-bridge-ros2dds, CDR), in the FRI 1
or FRI 2 layout (``[lbr] fri_major``; the other layout is named at its
first state and arming refused). Joint velocity is estimated from the
positions (:class:`~robot.lbr.guards.VelocityFilter`). The stack
low-passes measured and external torque (10 Hz by default); the adapter
recovers the raw torques from consecutive states
(:class:`~robot.lbr.compensation.TorqueUnfilter`). The tool wrench comes
from the external torques through our model (``F = (J J^T + l^2 I)^-1 J
tau_ext`` at the pad, world axes) or, with ``wrench_source = "stack"``, from
the stack's estimate (tip frame, soft deadband, brought to the pad:
:func:`~robot.lbr.tip.stack_wrench_to_tcp`).

Commands: the robot runs joint impedance at the app's stiffness (200
Nm/rad) towards the joint position the stack's PID makes of the message's
``joint_position``; the torque overlay is added. The adapter steers that
position onto the arm and takes the spring's rest off the overlay
(:class:`~robot.lbr.compensation.JointSpring`), so the joints get the
controller's torque (spread over the FRI cycles a slower controller
manager applies one message for). Nothing is sent before the adapter is
**armed**: with ``--arm`` (``[lbr] arm = true``) at the first controller
command the robot allows, or by an :class:`~interfaces.messages.ArmRequest`
on ``robot/arm``. Arming is refused, the reason named, unless the stack and
the robot are as :func:`~robot.lbr.arming.arming_refusal` needs. Every command passes
:func:`~robot.lbr.guards.guard_trip` first; a trip disarms.

**A stop that stops.** The stack re-applies the last message for as long as it runs and answers every FRI
cycle itself (lbr_torque_command_controller.cpp:42-55, async_client.cpp:74-93): no FRI watchdog fires.
Holding and disarming send a *hold* (``joint_position`` the measured pose, zero overlay: the stack's PID leaves
its command where it is, the robot's joint spring-damper brings the arm to rest), new in answer to every state
for as long as the adapter runs; a frozen target would have the PID integrate towards it. The adapter's last
message is the *release* (:mod:`robot.lbr.release`: the stack re-initialises its command at the measured pose,
safe under either damping law); if it dies without one, the watchdog (:mod:`robot.lbr.watchdog`) sends it.

Hold (a late or missing controller answer, ``hold``): the last command again while it is younger than
``stale_limit_s`` (one late answer must not step the torque), then the brake (:mod:`robot.lbr.brake`: the pad
stopped in the board's plane, its press kept and ramped out); after ``hold_timeout_s`` the adapter disarms. A
state whose commanded torque is no recent overlay of ours says the robot ran on an old message (ours do not reach
the stack): the server reports no command applied for it (:meth:`LbrPort.applying`, ``check_applied``), so the
controller stands still instead of winding up. Speed brake: the adapter declares the guard's joint speeds; the
server holds above ``speed_brake_share`` of them.

The link (:mod:`robot.lbr.watches` cites the stack): liveness from the robot's clock (a lost FRI link leaves
the stack re-publishing its last state): a stamp still for ``frozen_stamp_periods`` after our answer, a changed
sample time or a clock going back disarm; the connection quality warned about from FAIR, disarmed on at
``disarm_at_quality``; the applied check tolerant of the robot's resolution, disarming after ``applied_stall_s``
with no state on a recent overlay. At rest (:mod:`robot.lbr.rest_checks`): a pad pressing refuses arming, a
tool mass off the load data is named at arming. Every disarm says why (log, status). When the robot leaves
COMMANDING_ACTIVE the stack exits (system_interface.cpp:307-318): launch it again before the adapter can arm.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import numpy as np

from interfaces.messages import ArmRequest, Capabilities
from arm.robot_model import RobotModel
from runtime.session import CONTROL_QOS, ServiceNode
from robot.port import Applied, Reading, RobotPort

from .arming import REST_SPEED_RAD_S, arming_refusal, left_commanding
from .brake import ContactBrake
from .compensation import AppliedWatch, FreezeWatch, JointSpring, TorqueUnfilter
from .guards import GuardLimits, VelocityFilter, guard_trip
from .msgs import (ConnectionQuality, LbrState, LbrWireError, SessionState, decode_joint_names, decode_state,
                   decode_wrench, encode_torque_command, enum_name)
from .params import LbrParams
from .release import RELEASE_BYTES
from .rest_checks import load_note, pad_wrench
from .tip import stack_wrench_to_tcp
from .watches import Clock, ClockWatch, QualityWatch, TorqueResolution, quality_name

log = logging.getLogger(__name__)

#: The most FRI cycles a message is taken to be applied for (a longer gap between states is a gap, not a rate).
MAX_CYCLES_PER_STATE = 20


class LbrPort(RobotPort):
    """The real robot behind the bridge. See the module docstring.

    Parameters
    ----------
    params : LbrParams. node : an open ServiceNode (its raw session reaches the bridge's keys, its
    prefix the cell's). model : the robot description (limits, Jacobian).
    """

    clocked = True

    def __init__(self, params: LbrParams, node: ServiceNode, model: RobotModel | None = None) -> None:
        self.p = params
        self.node = node
        self.model = model or RobotModel()
        lim = self.model.limits
        self.capabilities = Capabilities(True, lim.tau_max.tolist(), "lbr")
        self.limits = GuardLimits(lim.q_min, lim.q_max, lim.dq_max * params.max_joint_speed_scale, lim.tau_max,
                                  params.limit_margin_rad, params.tau_rate_nm_s)
        # the server brakes (holds) below the guard's speed, before a joint whipping after a stall disarms
        self.velocity_limits_rad_s = self.limits.dq_max_rad_s
        self._zeros = np.zeros(7)
        self.counts: Counter[str] = Counter()
        self.armed = False
        self.arm_pending = params.arm
        self.disarm_reason = "not armed yet"
        self._velocity = VelocityFilter(7, params.velocity_cutoff_hz)
        self._tau_measured = TorqueUnfilter(params.measured_torque_cutoff_hz)
        self._tau_external = TorqueUnfilter(params.external_torque_cutoff_hz)
        self.spring = JointSpring(np.array(params.joint_stiffness_nm_rad), params.pid_p, params.steer_share,
                                  params.steer_speed_rad_s)
        self._freeze = FreezeWatch(params.frozen_after_s)
        self._brake = ContactBrake(self.model, params.hold_timeout_s, params.arm_preload_max_n)
        self._cond = threading.Condition()
        self._wake: threading.Event | None = None
        self._inbox: tuple[LbrState, int] | None = None  # the newest state and its arrival [monotonic ns]
        self._state: LbrState | None = None
        self._layout_error = ""
        self._reading = Reading(np.zeros(7), np.zeros(7), np.zeros(7), np.zeros(6), 0, dq_estimated=True)
        self._stack_wrench: np.ndarray | None = None
        self._ext_wrench = np.zeros(6)  # the pad wrench the external torque explains (world axes)
        self._rest = (np.zeros(6), None)  # that wrench in the newest state at rest, and its robot time [ns]
        self.load_note = ""  # the tool mass the external torque at rest implied at arming, when off
        self._names_ok: bool | None = None
        self._tau_prev: np.ndarray | None = None  # the controller's last torque sent
        self._tau_prev_ns = 0
        self._overlay = np.zeros(7)  # the overlay last sent
        self._has_sent = False
        self._holding_since_ns: int | None = None
        self._last_state_ns: int | None = None
        self._sent = AppliedWatch(tol_nm=params.applied_tolerance_nm)  # the overlays sent: did the robot run on one?
        self._resolution = TorqueResolution(params.applied_tolerance_nm, params.applied_tolerance_max_nm)
        self._applying = True
        self._clock = ClockWatch(params.frozen_stamp_periods)
        self._quality = QualityWatch(ConnectionQuality[params.disarm_at_quality])
        self._answered = (-1, 0)  # (the robot time of the reading our last message answered, when we first did)
        self._armed_ns = 0  # the robot time at arming
        self._cycles_per_state = 1  # FRI cycles between the newest two states: how long a message will be applied
        self._robot_waits = False  # the server runs lock-step: the robot's clock waits for our answers
        topics = params.topics
        s = node.session
        self._subs = [s.declare_subscriber(topics.key(topics.state), self._on_state),
                      s.declare_subscriber(topics.key(topics.joint_states), self._on_joint_states)]
        if params.wrench_source == "stack":
            self._subs.append(s.declare_subscriber(topics.key(topics.wrench), self._on_wrench))
        self._command_pub = s.declare_publisher(topics.key(topics.torque_command), **CONTROL_QOS)  # at once, first
        self._arm_requests = node.latest(node.keys.robot_arm, ArmRequest)

    # -- network callbacks (Zenoh's thread: decode, count, hand over) ------------------------------
    def _on_state(self, sample) -> None:
        try:
            st = decode_state(sample.payload.to_bytes(), self.p.fri_major)
        except LbrWireError as exc:
            text = str(exc)
            if "set [lbr] fri_major" in text:
                if not self._layout_error:
                    log.error("lbr: %s", text)
                self._layout_error = text
            self.counts[f"states_dropped: {text[:60]}"] += 1
            return
        with self._cond:
            self.counts["states_received"] += 1
            self._inbox = (st, time.monotonic_ns())
            self._cond.notify()
        if self._wake is not None:
            self._wake.set()

    def _on_joint_states(self, sample) -> None:
        try:
            names = decode_joint_names(sample.payload.to_bytes())
        except LbrWireError:
            self.counts["joint_states_dropped: not a JointState"] += 1
            return
        ok = tuple(names) == self.p.joint_names
        if not ok:
            self.counts[f"joint_states_dropped: names {list(names)[:8]}"] += 1
        self._names_ok = ok

    def _on_wrench(self, sample) -> None:
        try:
            _, w = decode_wrench(sample.payload.to_bytes())
        except LbrWireError as exc:
            self.counts[f"wrench_dropped: {str(exc)[:60]}"] += 1
            return
        self._stack_wrench = w

    # -- the port ----------------------------------------------------------------------------------
    def wait_reading(self, timeout_s: float) -> bool:
        """Wait for the next LBRState with a new time stamp; update velocity, torques, wrench, arming state, and the
        watches on the robot's clock, its connection quality and the commands it applied."""
        with self._cond:
            if self._inbox is None and not self._cond.wait_for(lambda: self._inbox is not None, timeout_s):
                self._poll_arm_requests()
                self._check_states_flow()
                return False
            (st, arrival_ns), self._inbox = self._inbox, None
        self._last_state_ns = time.monotonic_ns()  # a re-sent state too: the robot is there, waiting
        answered = self._answered[1] if self._answered[0] == self._clock.stamp_ns and not self._robot_waits else None
        clock = self._clock.update(st.stamp_ns, st.sample_time_s, arrival_ns, answered)
        if clock in (Clock.REPEATED, Clock.FROZEN):
            self.counts["states_repeated"] += 1  # a manager faster than the FRI cycle, or a peer waiting: nothing new
            if clock == Clock.FROZEN:
                self.counts["frozen_stamps"] += 1
                self._link_fault(self._clock.reason)
            self._poll_arm_requests()
            return False
        # the state period: the FRI's, or the controller manager's when it runs slower (its states come slower)
        period_s = st.sample_time_s if self._state is None else \
            max(st.sample_time_s, (st.stamp_ns - self._state.stamp_ns) * 1e-9)
        self._cycles_per_state = min(max(round(period_s / st.sample_time_s), 1), MAX_CYCLES_PER_STATE)
        self._take(st)
        if clock != Clock.ADVANCED:
            self.counts["clock_went_back" if clock == Clock.WENT_BACK else "sample_time_changes"] += 1
            self._link_fault(self._clock.reason)
        self._watch_quality(st)
        self._poll_arm_requests()
        self._check_session()
        self._watch_applied(st, period_s)
        if self.armed:
            why = self._freeze.update(st.q_rad, st.stamp_ns, self._overlay)
            if why is not None:
                self.counts["frozen_positions"] += 1
                self.disarm(why)
        return True

    def _link_fault(self, reason: str) -> None:
        """The robot's clock says the link failed: disarm (the hold goes out); disarmed, the status says it."""
        log.error("lbr: %s", reason)
        if self.armed:
            self.disarm(reason)
        else:
            self.disarm_reason = reason

    def _watch_quality(self, st: LbrState) -> None:
        """Log a change of the FRI connection quality (a warning from FAIR down); disarm at ``disarm_at_quality``."""
        event = self._quality.update(st.connection_quality)
        if event is not None:
            level, text = event
            log.log(level, "lbr: %s", text)
        if self.armed:
            why = self._quality.disarm_reason()
            if why is not None:
                self.counts["quality_disarms"] += 1
                self.disarm(why)

    def _watch_applied(self, st: LbrState, period_s: float) -> None:
        """Whether the robot ran on a recent overlay of ours (:class:`AppliedWatch`, within the robot's learned
        resolution); armed and none for ``applied_stall_s`` of robot time: disarm and say which it is."""
        self._resolution.update(st.tau_commanded_nm)
        checking = self.armed and self.p.check_applied
        # answer, manager cycle, FRI cycles applying and reporting it, manager cycle publishing: 2 periods of each
        self._applying = not (checking and self._sent.old(st.tau_commanded_nm, st.stamp_ns,
                                                           self.p.stale_limit_s + 2.0 * (period_s + st.sample_time_s),
                                                           self._resolution.tolerance_nm()))
        if not self._applying:
            self.counts["states_on_an_old_command"] += 1
        if not (checking and self._sent.sent_any):
            return
        since_ns = st.stamp_ns - (self._sent.applied_ns if self._sent.applied_ns is not None else self._armed_ns)
        if since_ns * 1e-9 > self.p.applied_stall_s:
            self.counts["applied_stalls"] += 1
            self.disarm(self._sent.stall_reason(since_ns * 1e-9, self._resolution.tolerance_nm()))

    def after_cycle(self, lockstep: bool) -> None:
        """In lock-step the robot waits for each answer (the simulated stack's lock-step), so its clock standing
        still while we are slow is no lost link: the clock watch does not judge it."""
        self._robot_waits = lockstep

    def applying(self) -> bool:
        """False while the newest state's commanded torque is an old overlay of ours or none of them
        (:class:`~robot.lbr.compensation.AppliedWatch`; ``[lbr] check_applied``)."""
        return self._applying

    def set_wake(self, wake: threading.Event) -> None:
        self._wake = wake

    def read(self) -> Reading:
        return self._reading

    def write(self, tau_nm: np.ndarray) -> Applied:
        why = self._cannot_arm() if not self.armed and self.arm_pending else None
        if not self.armed and not (self.arm_pending and why is None
                                   and self.arm("--arm at start-up, and the controller answers")):
            self.disarm_reason = f"waiting to arm (--arm): {why}" if why else self.disarm_reason
            self.counts["commands_while_disarmed"] += 1
            self._send_hold_if_stopped()
            return Applied.DISARMED
        r = self._reading
        # the rate guard compares with the last sent command over the robot time since (late cycles in between)
        since_s = (r.robot_time_ns - self._tau_prev_ns) * 1e-9 if self._tau_prev is not None else None
        reason = guard_trip(r.q_rad, r.dq_rad_s, tau_nm, self._tau_prev, self._state.sample_time_s, self.limits,
                            since_s)
        if reason is not None:
            self.counts["guard_trips"] += 1
            self.disarm(f"guard: {reason}")
            return Applied.DISARMED
        target, overlay = self.spring.command(r.q_rad, np.asarray(tau_nm, float), r.dq_rad_s,
                                              self._state.sample_time_s, self._cycles_per_state)
        self._send(target, overlay)
        self._tau_prev, self._tau_prev_ns = np.array(tau_nm, float), r.robot_time_ns
        self._holding_since_ns = None
        self.counts["commands_sent"] += 1
        return Applied.TORQUES

    def hold(self) -> Applied:
        """Hold this cycle: the last command again while it is younger than ``stale_limit_s`` (a late answer must
        not step the torque), then the brake (:mod:`robot.lbr.brake`); disarm after ``hold_timeout_s``."""
        if not self.armed:
            self._send_hold_if_stopped()
            return Applied.HELD
        r, now = self._reading, time.monotonic_ns()
        repeat = self._tau_prev is not None and (r.robot_time_ns - self._tau_prev_ns) * 1e-9 <= self.p.stale_limit_s
        if not repeat and self._holding_since_ns is None:
            self._holding_since_ns = now
            self._brake.start(r.q_rad, r.wrench_world, r.robot_time_ns)
        elif not repeat and (now - self._holding_since_ns) * 1e-9 > self.p.hold_timeout_s:
            self.disarm(f"no controller command for {(now - self._holding_since_ns) / 1e6:.0f} ms: holding the "
                        "measured pose on the robot's joint impedance")
            return Applied.HELD
        tau = self._tau_prev if repeat else self._brake.torque(r.dq_rad_s, r.robot_time_ns)
        self._send(*self.spring.command(r.q_rad, tau, r.dq_rad_s, self._state.sample_time_s, self._cycles_per_state))
        self.counts["commands_repeated" if repeat else "holds_sent"] += 1
        return Applied.HELD

    def speed_hold(self) -> Applied:
        """A joint too fast (the server's speed brake): the hold at once, no repeat of the last command; past a
        guard (the joint's speed over the guard's, a position limit ahead), disarm as a command would."""
        if not self.armed:
            self._send_hold_if_stopped()
            return Applied.BRAKED
        r = self._reading
        reason = guard_trip(r.q_rad, r.dq_rad_s, self._zeros, None, self._state.sample_time_s, self.limits)
        if reason is not None:
            self.counts["guard_trips"] += 1
            self.disarm(f"guard: {reason}")  # which sends the hold
        else:
            self._send_hold()
            self.counts["speed_holds_sent"] += 1
        return Applied.BRAKED

    def estop_hold(self) -> Applied:
        """E-stop: the hold at once (no repeat of the last command)."""
        if self.armed:
            self._send_hold()
            self.counts["estop_holds_sent"] += 1
        else:
            self._send_hold_if_stopped()
        return Applied.ESTOP_HELD

    def activate(self) -> None:
        log.info("lbr: monitoring %s (commands only once armed)", self.p.topics.key(self.p.state_topic))

    def deactivate(self) -> None:
        self.disarm("stopped")

    # -- arming ------------------------------------------------------------------------------------
    def arm(self, reason: str = "") -> bool:
        """Start commanding if the robot allows it; False (and why, logged and in the status) otherwise."""
        if self.armed:
            return True
        why = self._cannot_arm()
        if why is not None:
            self.counts["arm_refused"] += 1
            log.warning("lbr: refusing to arm: %s", why)
            self.disarm_reason = f"arming refused: {why}"
            return False
        st = self._state
        self.spring.reset(st.q_commanded_rad if st.q_commanded_rad is not None else st.q_rad, st.stamp_ns)
        self._freeze.reset()
        self.armed, self.arm_pending = True, False
        self._armed_ns = st.stamp_ns
        self.disarm_reason = ""  # the status's why= is for not commanding; an old refusal must not show
        self._tau_prev, self._holding_since_ns = None, None
        self._sent.reset()  # what the robot ran on before arming is not judged
        self.counts["arms"] += 1
        log.warning("lbr: ARMED (%s): commanding torques", reason or "request")
        w, rest_ns = self._rest  # the newest state at rest, up to 0.5 s before arming
        self.load_note = load_note(w, self.p.tool_mass_kg, self.p.tool_mass_tolerance_kg) or "" \
            if rest_ns is not None and st.stamp_ns - rest_ns <= 500_000_000 else ""
        if self.load_note:
            self.counts["load_mismatches"] += 1
            log.warning("lbr: %s", self.load_note)
        return True

    def disarm(self, reason: str) -> None:
        """Stop commanding torques now: the hold (the measured pose, zero overlay) from here on, as long as this
        runs."""
        if self.armed:
            self.armed = False
            self._send_hold()
            self.counts["disarms"] += 1
            log.warning("lbr: disarmed: %s", reason)
        self.arm_pending = False
        self.disarm_reason = reason

    def _cannot_arm(self) -> str | None:
        return arming_refusal(self._state, self.p, layout_error=self._layout_error, names_ok=self._names_ok,
                              clock=self._clock, dq_rad_s=self._reading.dq_rad_s, wrench=self._ext_wrench)

    def _poll_arm_requests(self) -> None:
        req = self._arm_requests.take()
        if req is not None:
            if req.armed:
                self.arm(f"request from {req.source[:40] or 'unknown'}: {req.reason[:80]}")
            else:
                self.disarm(f"disarm request from {req.source[:40] or 'unknown'}: {req.reason[:80]}")

    def _check_states_flow(self) -> None:
        """Armed without a robot state for ``hold_timeout_s`` (the stack or the bridge gone): disarm, so that the
        adapter never resumes commanding from a stale picture when states come back."""
        if self.armed and self._last_state_ns is not None:
            silent_s = (time.monotonic_ns() - self._last_state_ns) * 1e-9
            if silent_s > self.p.hold_timeout_s:
                self.disarm(f"no robot state for {silent_s * 1e3:.0f} ms (the stack exits when the robot leaves "
                            f"COMMANDING_ACTIVE: launch it again; or the bridge is gone){self._quality.note()}")

    def _check_session(self) -> None:
        why = left_commanding(self._state) if self.armed else None
        if why is not None:
            self.disarm(why + self._quality.note())

    # -- pieces ------------------------------------------------------------------------------------
    def _take(self, st: LbrState) -> None:
        if self._state is None or st.sample_time_s != self._state.sample_time_s:
            caps = self.capabilities  # the robot's rate is what its states say (the FRI send period)
            self.capabilities = Capabilities(caps.gravity_compensated, caps.torque_limits_nm, caps.backend,
                                             1.0 / st.sample_time_s if st.sample_time_s > 0 else 0.0)
        self._state = st
        r = self._reading
        r.q_rad = st.q_rad
        r.dq_rad_s = self._velocity.update(st.q_rad, st.stamp_ns).copy()
        r.tau_nm = self._tau_measured.update(st.tau_measured_nm, st.stamp_ns, st.sample_time_s).copy()
        tau_ext = self._tau_external.update(st.tau_external_nm, st.stamp_ns, st.sample_time_s)
        r.robot_time_ns = st.stamp_ns
        self.spring.observe(st.q_rad, st.stamp_ns, st.sample_time_s, st.q_commanded_rad, st.tau_commanded_nm,
                            self._resolution.tolerance_nm())
        if self.p.wrench_source == "stack":  # the stack's estimate; the rest checks use the external torque's
            w = self._stack_wrench
            r.wrench_world = np.zeros(6) if w is None else stack_wrench_to_tcp(
                self.model, st.q_rad, w, self.p.wrench_force_threshold_n, self.p.wrench_torque_threshold_nm)
        self._ext_wrench = pad_wrench(self.model, st.q_rad, tau_ext)
        if float(np.max(np.abs(r.dq_rad_s))) <= REST_SPEED_RAD_S:
            self._rest = (self._ext_wrench, st.stamp_ns)
        if self.p.wrench_source != "stack":
            r.wrench_world = self._ext_wrench

    def _send(self, joint_position: np.ndarray, overlay: np.ndarray) -> None:
        self._command_pub.put(encode_torque_command(joint_position, overlay))
        self._overlay = np.asarray(overlay, float)
        self._has_sent = True
        if self._answered[0] != self._reading.robot_time_ns:
            self._answered = (self._reading.robot_time_ns, time.monotonic_ns())
        self._sent.sent(self._overlay, self._reading.robot_time_ns)

    def _send_hold(self) -> None:
        """The hold: joint_position the measured pose, zero overlay. The stack's PID then leaves its command where
        it is (its input, target - measured, stays near zero), and the robot's joint spring-damper brings the arm
        to rest there; a pad pressed on a surface backs off until the spring balances it (no integrator pushes)."""
        if self._state is None:
            return
        q = np.array(self._state.q_rad, float)
        self._send(q, self._zeros)
        self.spring.hold(q)

    def _send_hold_if_stopped(self) -> None:
        """A disarmed adapter that has commanded keeps sending its hold in answer to every state."""
        if self._has_sent and self._state is not None:
            self._send_hold()
            self.counts["stop_holds_sent"] += 1

    def counters(self) -> dict[str, int]:
        counts = dict(self.counts, torques_passed_filtered=self._tau_external.passed_filtered,
                      connection_quality_warnings=self._quality.warnings,
                      applied_tolerance_unm=round(self._resolution.tolerance_nm() * 1e6))
        if self._quality.quality is not None:
            counts["connection_quality"] = self._quality.quality
        return counts

    def detail(self) -> str:
        session = enum_name(SessionState, self._state.session_state) if self._state is not None else "none"
        return (f"armed={self.armed} session={session} quality={quality_name(self._quality.quality)} "
                f"fri={self.p.fri_major} "
                f"why={self.disarm_reason[:240]!r}" + (f" load={self.load_note[:160]!r}" if self.load_note else ""))

    def close(self) -> None:
        if self._has_sent:  # the last message: the release, not a hold the stack's PID would integrate towards
            self._command_pub.put(RELEASE_BYTES)  # (the stack re-initialises its command at the measured pose)
            log.warning("lbr: sent the release")
        for sub in self._subs:
            sub.undeclare()
        self._subs = []
        self._command_pub.undeclare()

