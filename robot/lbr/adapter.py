"""The KUKA LBR iiwa through lbr_fri_ros2_stack, as a clocked :class:`~robot.port.RobotPort`.

Built against the stack as its code behaves (lbr_fri_ros2_stack ``rolling`` 218d723 and ``humble`` cca24ae;
docs/real-robot.md has the table):

States: the stack's ``LBRState`` (zenoh-bridge-ros2dds, CDR), in the FRI 1 or FRI 2 layout (``[lbr]
fri_major``; the other layout is named at its first state and arming refused). Joint velocity is estimated from
the positions (:class:`~robot.lbr.guards.VelocityFilter`). The stack low-passes measured and external torque (10
Hz by default); the adapter recovers the raw torques from consecutive states
(:class:`~robot.lbr.compensation.TorqueUnfilter`). The tool wrench comes
from the external torques through our model (``F = (J J^T + l^2 I)^-1 J
tau_ext`` at the pad, world axes) or, with ``wrench_source = "stack"``, from
the stack's estimate (tip frame, soft deadband, brought to the pad:
:func:`~robot.lbr.tip.stack_wrench_to_tcp`).

Commands: the robot runs joint impedance at the app's stiffness (200 Nm/rad) towards the joint position the
stack's PID makes of the message's ``joint_position``; the torque overlay is added. The adapter steers that
position onto the arm and takes the spring's rest off the overlay (:class:`~robot.lbr.compensation.JointSpring`),
so the joints get the controller's torque (spread over the FRI cycles a slower controller manager applies one
message for). Nothing is sent before the adapter is **armed**: with ``--arm`` (``[lbr] arm = true``) at the first
controller command the robot allows, or by an :class:`~interfaces.messages.ArmRequest` on ``robot/arm``. Arming
is refused, the reason named, unless the stack and the robot are as :func:`~robot.lbr.arming.arming_refusal`
needs. Every command passes :func:`~robot.lbr.guards.guard_trip` first; a trip disarms.

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
import zenoh

from interfaces.messages import ArmRequest, Capabilities
from arm.robot_model import RobotModel
from runtime.session import CONTROL_QOS, ServiceNode
from robot.port import Applied, Reading, RobotPort

from .arming import ArmState, arming_refusal, left_commanding
from .brake import ContactBrake
from .commands import CommandSender, HeldCommand
from .compensation import JointSpring
from .guards import GuardLimits, guard_trip
from .inbox import StateInbox
from .msgs import ConnectionQuality, LbrState, SessionState, enum_name
from .params import LbrParams
from .readings import StateReadings
from .watches import AppliedCheck, Clock, LinkWatch, quality_name

log = logging.getLogger(__name__)


def command_qos(lockstep: bool) -> dict:
    """The torque command key's publisher options: at once, first (``CONTROL_QOS``). A real robot runs on when an
    answer is late, so a congested link drops ours rather than queue an old one; a lock-step robot waits for each
    answer and has no second one coming (``LBRTorqueCommand`` carries no sequence number to re-answer by): there
    a dropped answer would cost the peer its ``lockstep_wait_s`` and run the arm on an old message, so the key
    blocks instead."""
    if not lockstep:
        return CONTROL_QOS
    return {**CONTROL_QOS, "congestion_control": zenoh.CongestionControl.BLOCK}


class LbrPort(RobotPort):
    """The real robot behind the bridge. See the module docstring.

    Parameters
    ----------
    params : LbrParams. node : an open ServiceNode (its raw session reaches the bridge's keys, its
    prefix the cell's). model : the robot description (limits, Jacobian). lockstep : the server runs lock-step
    with a robot that waits for each answer (the simulated stack's lock-step): the command key then blocks under
    congestion instead of dropping (:func:`command_qos`).

    What it keeps, by purpose: the states as they arrive (:class:`~robot.lbr.inbox.StateInbox`) and the reading
    made of the newest (:class:`~robot.lbr.readings.StateReadings`); whether it commands
    (:class:`~robot.lbr.arming.ArmState`); the watches on the link and on the commands applied
    (:class:`~robot.lbr.watches.LinkWatch`, :class:`~robot.lbr.watches.AppliedCheck`); the messages sent and the
    hold after the controller's last command (:class:`~robot.lbr.commands.CommandSender`,
    :class:`~robot.lbr.commands.HeldCommand`); the stack's joint spring (:attr:`spring`,
    :class:`~robot.lbr.compensation.JointSpring`). ``counts`` are its counters, shared with the inbox.
    """

    clocked = True

    def __init__(self, params: LbrParams, node: ServiceNode, model: RobotModel | None = None,
                 lockstep: bool = False) -> None:
        self.p = params
        self.node = node
        self.model = model or RobotModel()
        lim = self.model.limits
        self.capabilities = Capabilities(True, lim.tau_max.tolist(), "lbr")
        self.limits = GuardLimits(lim.q_min, lim.q_max, lim.dq_max * params.max_joint_speed_scale, lim.tau_max,
                                  params.limit_margin_rad, params.tau_rate_nm_s)
        # the server brakes (holds) below the guard's speed, before a joint whipping after a stall disarms
        self.velocity_limits_rad_s = self.limits.dq_max_rad_s
        self.counts: Counter[str] = Counter()
        self.spring = JointSpring(np.array(params.joint_stiffness_nm_rad), params.pid_p, params.steer_share,
                                  params.steer_speed_rad_s)
        self._arming = ArmState(pending=params.arm)
        self._readings = StateReadings(params, self.model)
        self._held = HeldCommand(ContactBrake(self.model, params.hold_timeout_s, params.arm_preload_max_n),
                                 params.stale_limit_s, params.hold_timeout_s)
        self._link = LinkWatch(params.frozen_stamp_periods, ConnectionQuality[params.disarm_at_quality],
                               params.frozen_after_s)
        # the overlays sent: did the robot run on one?
        self._applied = AppliedCheck(params.applied_tolerance_nm, params.applied_tolerance_max_nm,
                                     params.check_applied, params.stale_limit_s, params.applied_stall_s)
        self._inbox = StateInbox(params, node.session, self.counts, log)
        topics = params.topics
        self._out = CommandSender(node.session.declare_publisher(topics.key(topics.torque_command),
                                                                 **command_qos(lockstep)))
        self._arm_requests = node.latest(node.keys.robot_arm, ArmRequest)

    @property
    def armed(self) -> bool:
        """Whether the adapter commands torques."""
        return self._arming.armed

    @property
    def disarm_reason(self) -> str:
        """Why the adapter does not command (empty while armed)."""
        return self._arming.reason

    @property
    def load_note(self) -> str:
        """The tool mass the external torque at rest implied at arming, when off the load data (empty: none)."""
        return self._arming.load_note

    # -- the port ----------------------------------------------------------------------------------
    def wait_reading(self, timeout_s: float) -> bool:
        """Wait for the next LBRState with a new time stamp; update velocity, torques, wrench, arming state, and the
        watches on the robot's clock, its connection quality and the commands it applied."""
        inbox = self._inbox.wait(timeout_s)
        if inbox is None:
            self._poll_arm_requests()
            self._check_states_flow()
            return False
        st, arrival_ns = inbox
        clock = self._link.state(st, arrival_ns)
        if clock in (Clock.REPEATED, Clock.FROZEN):
            self.counts["states_repeated"] += 1  # a manager faster than the FRI cycle, or a peer waiting: nothing new
            if clock == Clock.FROZEN:
                self.counts["frozen_stamps"] += 1
                self._link_fault(self._link.clock.reason)
            self._poll_arm_requests()
            return False
        period_s = self._take(st)
        if clock != Clock.ADVANCED:
            self.counts["clock_went_back" if clock == Clock.WENT_BACK else "sample_time_changes"] += 1
            self._link_fault(self._link.clock.reason)
        self._watch_quality(st)
        self._poll_arm_requests()
        self._check_session()
        self._watch_applied(st, period_s)
        if self._arming.armed:
            why = self._link.freeze.update(st.q_rad, st.stamp_ns, self._out.overlay)
            if why is not None:
                self.counts["frozen_positions"] += 1
                self.disarm(why)
        return True

    def _link_fault(self, reason: str) -> None:
        """The robot's clock says the link failed: disarm (the hold goes out); disarmed, the status says it."""
        log.error("lbr: %s", reason)
        if self._arming.armed:
            self.disarm(reason)
        else:
            self._arming.reason = reason

    def _watch_quality(self, st: LbrState) -> None:
        """Log a change of the FRI connection quality (a warning from FAIR down); disarm at ``disarm_at_quality``."""
        quality = self._link.quality
        event = quality.update(st.connection_quality)
        if event is not None:
            level, text = event
            log.log(level, "lbr: %s", text)
        if self._arming.armed:
            why = quality.disarm_reason()
            if why is not None:
                self.counts["quality_disarms"] += 1
                self.disarm(why)

    def _watch_applied(self, st: LbrState, period_s: float) -> None:
        """Whether the robot ran on a recent overlay of ours (:class:`~robot.lbr.watches.AppliedCheck`); armed and
        none for ``applied_stall_s`` of robot time: disarm and say which it is."""
        why = self._applied.update(st, period_s, self._arming.armed)
        if not self._applied.applying:
            self.counts["states_on_an_old_command"] += 1
        if why is not None:
            self.counts["applied_stalls"] += 1
            self.disarm(why)

    def after_cycle(self, lockstep: bool) -> None:
        """In lock-step the robot waits for each answer (the simulated stack's lock-step), so its clock standing
        still while we are slow is no lost link: the clock watch does not judge it."""
        self._link.robot_waits = lockstep

    def applying(self) -> bool:
        """False while the newest state's commanded torque is an old overlay of ours or none of them
        (:class:`~robot.lbr.compensation.AppliedWatch`; ``[lbr] check_applied``)."""
        return self._applied.applying

    def set_wake(self, wake: threading.Event) -> None:
        self._inbox.set_wake(wake)

    def read(self) -> Reading:
        return self._readings.reading

    def write(self, tau_nm: np.ndarray) -> Applied:
        a = self._arming
        why = self._cannot_arm() if not a.armed and a.pending else None
        if not a.armed and not (a.pending and why is None
                                and self.arm("--arm at start-up, and the controller answers")):
            a.reason = f"waiting to arm (--arm): {why}" if why else a.reason
            self.counts["commands_while_disarmed"] += 1
            self._send_hold_if_stopped()
            return Applied.DISARMED
        rd, held = self._readings, self._held
        r = rd.reading
        # the rate guard compares with the last sent command over the robot time since (late cycles in between)
        reason = guard_trip(r.q_rad, r.dq_rad_s, tau_nm, held.tau_nm, rd.sample_s, self.limits,
                            held.since_s(r.robot_time_ns))
        if reason is not None:
            self.counts["guard_trips"] += 1
            self.disarm(f"guard: {reason}")
            return Applied.DISARMED
        target, overlay = self.spring.command(r.q_rad, np.asarray(tau_nm, float), r.dq_rad_s,
                                              rd.sample_s, rd.cycles_per_state)
        self._send(target, overlay)
        held.commanded(tau_nm, r.robot_time_ns)
        self.counts["commands_sent"] += 1
        return Applied.TORQUES

    def hold(self) -> Applied:
        """Hold this cycle: the last command again while it is younger than ``stale_limit_s`` (a late answer must
        not step the torque), then the brake (:mod:`robot.lbr.brake`); disarm after ``hold_timeout_s``
        (:class:`~robot.lbr.commands.HeldCommand`)."""
        if not self._arming.armed:
            self._send_hold_if_stopped()
            return Applied.HELD
        rd, held, now = self._readings, self._held, time.monotonic_ns()
        r = rd.reading
        tau = held.torque(r, now)
        if tau is None:
            self.disarm(f"no controller command for {held.held_ms(now):.0f} ms: holding the "
                        "measured pose on the robot's joint impedance")
            return Applied.HELD
        self._send(*self.spring.command(r.q_rad, tau, r.dq_rad_s, rd.sample_s, rd.cycles_per_state))
        self.counts["commands_repeated" if held.repeated else "holds_sent"] += 1
        return Applied.HELD

    def speed_hold(self) -> Applied:
        """A joint too fast (the server's speed brake): the hold at once, no repeat of the last command; past a
        guard (the joint's speed over the guard's, a position limit ahead), disarm as a command would."""
        if not self._arming.armed:
            self._send_hold_if_stopped()
            return Applied.BRAKED
        r = self._readings.reading
        reason = guard_trip(r.q_rad, r.dq_rad_s, self._out.zeros, None, self._readings.sample_s, self.limits)
        if reason is not None:
            self.counts["guard_trips"] += 1
            self.disarm(f"guard: {reason}")  # which sends the hold
        else:
            self._send_hold()
            self.counts["speed_holds_sent"] += 1
        return Applied.BRAKED

    def estop_hold(self) -> Applied:
        """E-stop: the hold at once (no repeat of the last command)."""
        if self._arming.armed:
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
        a = self._arming
        if a.armed:
            return True
        why = self._cannot_arm()
        if why is not None:
            self.counts["arm_refused"] += 1
            log.warning("lbr: refusing to arm: %s", why)
            a.reason = f"arming refused: {why}"
            return False
        st = self._readings.state
        assert st is not None, "armed without a state"  # _cannot_arm refuses that
        self.spring.reset(st.q_commanded_rad if st.q_commanded_rad is not None else st.q_rad, st.stamp_ns)
        self._link.freeze.reset()
        a.armed, a.pending = True, False
        a.reason = ""  # the status's why= is for not commanding; an old refusal must not show
        self._held.reset()
        self._applied.arm(st.stamp_ns)
        self.counts["arms"] += 1
        log.warning("lbr: ARMED (%s): commanding torques", reason or "request")
        if a.note_load(self.p.tool_mass_kg, self.p.tool_mass_tolerance_kg):
            self.counts["load_mismatches"] += 1
            log.warning("lbr: %s", a.load_note)
        return True

    def disarm(self, reason: str) -> None:
        """Stop commanding torques now: the hold (the measured pose, zero overlay) from here on, as long as this
        runs."""
        a = self._arming
        if a.armed:
            a.armed = False
            self._send_hold()
            self.counts["disarms"] += 1
            log.warning("lbr: disarmed: %s", reason)
        a.pending = False
        a.reason = reason

    def _cannot_arm(self) -> str | None:
        rd, inbox = self._readings, self._inbox
        return arming_refusal(rd.state, self.p, layout_error=inbox.layout_error, names_ok=inbox.names_ok,
                              clock=self._link.clock, dq_rad_s=rd.reading.dq_rad_s, wrench=rd.ext_wrench)

    def _poll_arm_requests(self) -> None:
        req = self._arm_requests.take()
        if req is not None:
            if req.armed:
                self.arm(f"request from {req.source[:40] or 'unknown'}: {req.reason[:80]}")
            else:
                self.disarm(f"disarm request from {req.source[:40] or 'unknown'}: {req.reason[:80]}")

    def _check_states_flow(self) -> None:
        """Armed without a robot state for ``hold_timeout_s`` (the stack or the bridge gone): disarm, so that the
        adapter never resumes commanding from a stale picture when states come back. In lock-step the robot
        publishes every step it takes and takes none while it is not scheduled, so a wall-clock gap there is a
        loaded machine, not a robot moving unseen: ``lockstep_silence_s`` (the controller's lock-step
        ``robot_lost_s`` default) applies instead."""
        if self._arming.armed:
            limit_s = self.p.lockstep_silence_s if self._link.robot_waits else self.p.hold_timeout_s
            why = self._link.silence(limit_s)
            if why is not None:
                self.disarm(why)

    def _check_session(self) -> None:
        st = self._readings.state
        why = left_commanding(st) if self._arming.armed and st is not None else None
        if why is not None:
            self.disarm(why + self._link.quality.note())

    # -- pieces ------------------------------------------------------------------------------------
    def _take(self, st: LbrState) -> float:
        """The state ``st`` (a new time stamp) into the reading; the state period [s]."""
        prev, rd = self._readings.state, self._readings
        if prev is None or st.sample_time_s != prev.sample_time_s:
            caps = self.capabilities  # the robot's rate is what its states say (the FRI send period)
            self.capabilities = Capabilities(caps.gravity_compensated, caps.torque_limits_nm, caps.backend,
                                             1.0 / st.sample_time_s if st.sample_time_s > 0 else 0.0)
        period_s = rd.take(st, self._inbox.stack_wrench)
        self.spring.observe(st.q_rad, st.stamp_ns, st.sample_time_s, st.q_commanded_rad, st.tau_commanded_nm,
                            self._applied.resolution.tolerance_nm())
        self._arming.observe_rest(rd.ext_wrench, rd.reading.dq_rad_s, st.stamp_ns, self.p.arm_preload_max_n)
        return period_s

    def _send(self, joint_position: np.ndarray, overlay: np.ndarray) -> None:
        t_ns = self._readings.reading.robot_time_ns
        self._out.send(joint_position, overlay)
        self._link.answer(t_ns)
        self._applied.sent.sent(self._out.overlay, t_ns)

    def _send_hold(self) -> None:
        """The hold: joint_position the measured pose, zero overlay. The stack's PID then leaves its command where
        it is (its input, target - measured, stays near zero), and the robot's joint spring-damper brings the arm
        to rest there; a pad pressed on a surface backs off until the spring balances it (no integrator pushes)."""
        st = self._readings.state
        if st is None:
            return
        self._send(q := np.array(st.q_rad, float), self._out.zeros)
        self.spring.hold(q)

    def _send_hold_if_stopped(self) -> None:
        """A disarmed adapter that has commanded keeps sending its hold in answer to every state."""
        if self._out.has_sent and self._readings.state is not None:
            self._send_hold()
            self.counts["stop_holds_sent"] += 1

    def counters(self) -> dict[str, int]:
        quality = self._link.quality
        counts = dict(self.counts, torques_passed_filtered=self._readings.passed_filtered,
                      connection_quality_warnings=quality.warnings,
                      applied_tolerance_unm=round(self._applied.resolution.tolerance_nm() * 1e6))
        if quality.quality is not None:
            counts["connection_quality"] = quality.quality
        return counts

    def detail(self) -> str:
        st, a = self._readings.state, self._arming
        session = enum_name(SessionState, st.session_state) if st is not None else "none"
        return (f"armed={a.armed} session={session} quality={quality_name(self._link.quality.quality)} "
                f"fri={self.p.fri_major} "
                f"why={a.reason[:240]!r}" + (f" load={a.load_note[:160]!r}" if a.load_note else ""))

    def close(self) -> None:
        if self._out.has_sent:  # the last message: the release, not a hold the stack's PID would integrate towards
            self._out.release()  # (the stack re-initialises its command at the measured pose)
            log.warning("lbr: sent the release")
        self._inbox.close()
        self._out.undeclare()
