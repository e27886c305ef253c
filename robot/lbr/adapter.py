"""The KUKA LBR iiwa through lbr_fri_ros2_stack, as a clocked :class:`~robot.port.RobotPort`.

States: the stack's ``LBRState`` (through zenoh-bridge-ros2dds, CDR) gives
the measured joint positions, measured and external torques, the FRI
sample time and the session, safety and drive states. Joint velocity is
estimated (:class:`~robot.lbr.guards.VelocityFilter`; the state says so);
the tool wrench comes from the external torques through our model
(``F = (J J^T + l^2 I)^-1 J tau_ext`` at the pad, world axes) or, with
``wrench_source = "stack"``, from the bridge's ``WrenchStamped``.
Capabilities: the robot compensates gravity itself; torque limits from the
description; the state rate from the FRI sample time in the states.

Commands: ``LBRTorqueCommand`` with the measured joint position and the
controller's torques as overlay. Nothing is sent until the adapter is
**armed**: with ``--arm`` (``[lbr] arm = true``) at the first controller
command the session allows, or by an :class:`~interfaces.messages.ArmRequest`
on ``robot/arm``; arming is refused unless the session says commanding is possible (COMMANDING_WAIT or
COMMANDING_ACTIVE), safety is normal and the drives are active. Every
command passes :func:`~robot.lbr.guards.guard_trip` first; a trip disarms.

Safe hold (a late or missing controller answer, or ``hold``): the last
command again while it is younger than ``stale_limit_s`` (one late answer
must not step the torque), then damping torques ``-D dq`` with the measured
joint position; after
``hold_timeout_s`` of holding the adapter disarms and stops commanding, so
that the robot's own FRI watchdog ends the session and the robot stops.
Speed brake: the adapter declares the guard's joint speeds as its velocity
limits, so the server holds (``joint_speed_brakes``) while a joint moves
faster than ``speed_brake_share`` of them or is about to by the next cycle,
below the guard that would disarm: after a stall in our own processes the
robot has repeated the last torque for tens of milliseconds, and the
controller's correction can whip a light wrist joint.

Disarming (stop, signal, controller loss, guard trip, session lost, no robot state for ``hold_timeout_s``) sends
one last hold and says why (log, status).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import numpy as np

from interfaces.messages import ArmRequest, Capabilities
from interfaces.robot_model import RobotModel
from interfaces.session import CONTROL_QOS, ServiceNode
from robot.port import Reading, RobotPort

from .guards import GuardLimits, VelocityFilter, guard_trip
from .msgs import (DriveState, LbrState, LbrWireError, SafetyState, SessionState, decode_joint_names, decode_state,
                   decode_wrench, encode_torque_command)
from .params import LbrParams

log = logging.getLogger(__name__)

COMMANDING = (SessionState.COMMANDING_WAIT, SessionState.COMMANDING_ACTIVE)
#: Damping of the pseudo-inverse that turns external joint torques into a tool wrench.
WRENCH_DAMPING = 0.01


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
        # the server brakes (holds) below the guard's speed, before a wrist whipping after a stall disarms
        self.velocity_limits_rad_s = self.limits.dq_max_rad_s
        self._zeros = np.zeros(7)
        self.counts: Counter[str] = Counter()
        self.armed = False
        self.arm_pending = params.arm
        self.disarm_reason = "not armed yet"
        self._velocity = VelocityFilter(7, params.velocity_cutoff_hz)
        self._hold_damping = np.array(params.hold_damping_nm_s_rad)
        self._cond = threading.Condition()
        self._wake: threading.Event | None = None
        self._inbox: LbrState | None = None
        self._state: LbrState | None = None
        self._reading = Reading(np.zeros(7), np.zeros(7), np.zeros(7), np.zeros(6), 0, dq_estimated=True)
        self._stack_wrench: np.ndarray | None = None
        self._names_ok: bool | None = None
        self._tau_prev: np.ndarray | None = None
        self._tau_prev_ns = 0
        self._holding_since_ns: int | None = None
        self._last_state_ns: int | None = None
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
            st = decode_state(sample.payload.to_bytes())
        except LbrWireError as exc:
            self.counts[f"states_dropped: {str(exc)[:60]}"] += 1
            return
        with self._cond:
            self.counts["states_received"] += 1
            self._inbox = st
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
        """Wait for the next LBRState with a new time stamp; update velocity, wrench and the arming state."""
        with self._cond:
            if self._inbox is None and not self._cond.wait_for(lambda: self._inbox is not None, timeout_s):
                self._poll_arm_requests()
                self._check_states_flow()
                return False
            st, self._inbox = self._inbox, None
        self._last_state_ns = time.monotonic_ns()  # a re-sent state too: the robot is there, waiting
        if self._state is not None and st.stamp_ns == self._state.stamp_ns:
            self.counts["states_repeated"] += 1  # a peer re-sending while it waits: nothing new
            return False
        self._take(st)
        self._poll_arm_requests()
        self._check_session()
        return True

    def set_wake(self, wake: threading.Event) -> None:
        self._wake = wake

    def read(self) -> Reading:
        return self._reading

    def write(self, tau_nm: np.ndarray) -> None:
        if not self.armed and not (self.arm_pending and self._cannot_arm() is None
                                   and self.arm("--arm at start-up, and the controller answers")):
            self.counts["commands_while_disarmed"] += 1
            return
        r = self._reading
        # the rate guard compares with the last sent command over the robot time since (late cycles in between)
        since_s = (r.robot_time_ns - self._tau_prev_ns) * 1e-9 if self._tau_prev is not None else None
        reason = guard_trip(r.q_rad, r.dq_rad_s, tau_nm, self._tau_prev, self._state.sample_time_s, self.limits,
                            since_s)
        if reason is not None:
            self.counts["guard_trips"] += 1
            self.disarm(f"guard: {reason}")
            return
        self._send(tau_nm)
        self._tau_prev = np.array(tau_nm, float)
        self._tau_prev_ns = r.robot_time_ns
        self._holding_since_ns = None
        self.counts["commands_sent"] += 1

    def hold(self) -> None:
        """Hold this cycle: the last command again while it is younger than ``stale_limit_s`` (a late answer must
        not step the torque), then damping torques with the measured position; disarm after ``hold_timeout_s``."""
        if not self.armed:
            return
        if self._tau_prev is not None and \
                (self._reading.robot_time_ns - self._tau_prev_ns) * 1e-9 <= self.p.stale_limit_s:
            self._send(self._tau_prev)
            self.counts["commands_repeated"] += 1
            return
        now = time.monotonic_ns()
        if self._holding_since_ns is None:
            self._holding_since_ns = now
        elif (now - self._holding_since_ns) * 1e-9 > self.p.hold_timeout_s:
            self.disarm(f"no controller command for {(now - self._holding_since_ns) / 1e6:.0f} ms: stopped "
                        "commanding (the robot's FRI watchdog stops it)")
            return
        self._send_hold()
        self.counts["holds_sent"] += 1

    def speed_hold(self) -> None:
        """A joint too fast (the server's speed brake): damping torques at once, no repeat of the last command;
        past a guard (the joint's speed over the guard's, a position limit ahead), disarm as a command would."""
        if not self.armed:
            return
        r = self._reading
        reason = guard_trip(r.q_rad, r.dq_rad_s, self._zeros, None, self._state.sample_time_s, self.limits)
        if reason is not None:
            self.counts["guard_trips"] += 1
            self.disarm(f"guard: {reason}")
            return
        self._send_hold()
        self.counts["speed_holds_sent"] += 1

    def estop_hold(self) -> None:
        """E-stop: damping torques with the measured position at once (no repeat of the last command)."""
        if self.armed:
            self._send_hold()
            self.counts["estop_holds_sent"] += 1

    def activate(self) -> None:
        log.info("lbr: monitoring %s (commands only once armed)", self.p.topics.key(self.p.state_topic))

    def deactivate(self) -> None:
        self.disarm("stopped")

    # -- arming ------------------------------------------------------------------------------------
    def arm(self, reason: str = "") -> bool:
        """Start commanding if the robot's session allows it; False (and why, logged) otherwise."""
        if self.armed:
            return True
        why = self._cannot_arm()
        if why is not None:
            self.counts["arm_refused"] += 1
            log.warning("lbr: refusing to arm: %s", why)
            self.disarm_reason = f"arming refused: {why}"
            return False
        self.armed, self.arm_pending = True, False
        self.disarm_reason = ""  # the status's why= is for not commanding; an old refusal must not show
        self._tau_prev, self._holding_since_ns = None, None
        self.counts["arms"] += 1
        log.warning("lbr: ARMED (%s): commanding torques", reason or "request")
        return True

    def disarm(self, reason: str) -> None:
        """Stop commanding now, after one last hold; the robot holds by itself once commands stop."""
        if self.armed:
            self._send_hold()
            self.armed = False
            self.counts["disarms"] += 1
            log.warning("lbr: disarmed: %s", reason)
        self.arm_pending = False
        self.disarm_reason = reason

    def _cannot_arm(self) -> str | None:
        st = self._state
        if st is None:
            return "no robot state received yet"
        if st.session_state not in COMMANDING:
            return (f"session state {_name(SessionState, st.session_state)}: start the LBRServer application "
                    "in torque command mode on the smartPAD first")
        if st.safety_state != SafetyState.NORMAL_OPERATION:
            return f"safety state {_name(SafetyState, st.safety_state)}"
        if st.drive_state != DriveState.ACTIVE:
            return f"drives {_name(DriveState, st.drive_state)}"
        if self._names_ok is False:
            return f"joint names on {self.p.joint_states_topic} are not {list(self.p.joint_names)}"
        return None

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
                self.disarm(f"no robot state for {silent_s * 1e3:.0f} ms (stack or bridge gone)")

    def _check_session(self) -> None:
        st = self._state
        if self.armed and (st.session_state not in COMMANDING or st.safety_state != SafetyState.NORMAL_OPERATION
                           or st.drive_state != DriveState.ACTIVE):
            self.disarm(f"robot left commanding (session {_name(SessionState, st.session_state)}, safety "
                        f"{_name(SafetyState, st.safety_state)}, drives {_name(DriveState, st.drive_state)})")

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
        r.tau_nm = st.tau_measured_nm
        r.robot_time_ns = st.stamp_ns
        if self.p.wrench_source == "stack":
            r.wrench_world = self._stack_wrench if self._stack_wrench is not None else np.zeros(6)
        else:
            J = self.model.tcp_jacobian(st.q_rad)
            r.wrench_world = np.linalg.solve(J @ J.T + WRENCH_DAMPING**2 * np.eye(6), J @ st.tau_external_nm)

    def _send(self, tau: np.ndarray) -> None:
        self._command_pub.put(encode_torque_command(self._state.q_rad, tau))

    def _send_hold(self) -> None:
        if self._state is None:
            return
        tau = np.clip(-self._hold_damping * self._reading.dq_rad_s, -self.limits.tau_max_nm,
                      self.limits.tau_max_nm)
        self._send(tau)

    def counters(self) -> dict[str, int]:
        return dict(self.counts)

    def detail(self) -> str:
        st = self._state
        session = _name(SessionState, st.session_state) if st is not None else "none"
        return f"armed={self.armed} session={session} why={self.disarm_reason[:120]!r}"

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs = []
        self._command_pub.undeclare()


def _name(enum, value: int) -> str:
    try:
        return enum(value).name
    except ValueError:
        return f"unknown({value})"
