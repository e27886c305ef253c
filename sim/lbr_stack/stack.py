"""The stack's and the robot's behaviours as pure state (numpy, SI units, joints A1..A7), no network, no physics.

Each class models code of lbr_fri_ros2_stack (``rolling`` 218d723 unless
said), of the FRI client SDK, or of the robot-side LBRServer app; the
file and line are in its docstring and in docs/real-robot.md.

* :class:`ExponentialFilter`: the stack's low-pass on measured and external
  torque (lbr_fri_ros2/src/filters.cpp:23-28, state.cpp:18,26,80-85).
* :class:`JointPid`: the stack's PID on the commanded joint position
  (filters.cpp:56-62, torque_command.cpp:33-37).
* :class:`StackClient`: the FRI client side of the stack (async_client.cpp,
  torque_command.cpp, base_command.cpp) and its ros2_control loop
  (system_interface.cpp, lbr_torque_command_controller.cpp).
* :class:`RobotSession`: the session states the robot reports, and its end of commanding on a poor link.
* :class:`FriLink`: the FRI link (lost for a while or for good) and the connection quality the robot reports.
* :func:`reported_commanded_torque`: the ``commanded_torque`` the robot reports for an overlay (an exact echo by
  default, or rounded, or off by a bias: the SDK documents it only as the robot's "last commanded joint torques").
* :func:`joint_impedance_torque`: the app's joint impedance with the torque
  overlay (LBRServer.java: JointImpedanceControlMode(200, ...)).
* :func:`estimated_wrench`: the stack's force-torque estimate (ft_estimator.cpp).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robot.lbr.compensation import filter_alpha
from robot.lbr.msgs import N_JOINTS, ClientCommandMode, ConnectionQuality, SessionState

from .params import COMMAND_MODES, LbrPeerParams


class ExponentialFilter:
    """``y = alpha x + (1 - alpha) y_prev`` per joint (control_toolbox's exponentialSmoothing).

    alpha is the stack's (filters.cpp:23-28, :func:`robot.lbr.compensation.filter_alpha`): 0, so the output never
    moves, at a cutoff of 0 and of exactly the sample rate (filters.cpp:13-17 clamps the stored cutoff to 1 / T but
    computes alpha from the argument). As the stack does (state.cpp:18,26 then 36-39): the first sample is filtered
    with the default filter (alpha 0, so the output stays at the zero it was built with), then alpha is set from the
    cutoff and the state's sample time.
    """

    def __init__(self, cutoff_hz: float, n: int = N_JOINTS) -> None:
        self.cutoff_hz = cutoff_hz
        self.alpha = 0.0
        self.y = np.zeros(n)
        self._initialized = False

    def update(self, x: np.ndarray, sample_time_s: float) -> np.ndarray:
        """Filter one sample ``x`` (n,); returns :attr:`y` (reused)."""
        self.y *= 1.0 - self.alpha
        self.y += self.alpha * x
        if not self._initialized:
            self.alpha = filter_alpha(self.cutoff_hz, sample_time_s)
            self._initialized = True
        return self.y


class JointPid:
    """The stack's joint position PID (filters.cpp:56-62): ``command += pid(target - measured, dt)`` per joint.

    control_toolbox's Pid: p e + the integral of i e dt clamped to [i_min, i_max] + d de/dt.
    """

    def __init__(self, p: float, i: float, d: float, i_max: float, i_min: float, n: int = N_JOINTS) -> None:
        self.kp, self.ki, self.kd, self.i_max, self.i_min = p, i, d, i_max, i_min
        self._integral = np.zeros(n)
        self._e_prev = np.zeros(n)

    def step(self, target: np.ndarray, measured: np.ndarray, dt_s: float, command: np.ndarray) -> None:
        """Add the PID's output to ``command`` (n,) in place."""
        e = target - measured
        out = self.kp * e
        if self.ki:
            self._integral = np.clip(self._integral + self.ki * e * dt_s, self.i_min, self.i_max)
            out = out + self._integral
        if self.kd and dt_s > 0:
            out = out + self.kd * (e - self._e_prev) / dt_s
        self._e_prev = e
        command += out


def joint_impedance_torque(overlay_nm: np.ndarray, q_cmd: np.ndarray, dq_cmd: np.ndarray, q: np.ndarray,
                           dq: np.ndarray, stiffness: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """(7,) [Nm] the robot applies in joint impedance with a torque overlay, gravity excluded.

    ``overlay + K (q_cmd - q) + D (dq_cmd - dq)``: a spring-damper from the commanded joint position
    (``q_cmd``, ``dq_cmd`` its rate) to the arm. K is the app's (LBRServer.java: 200 Nm/rad on every joint),
    D the damping the ratio gives with the joint's inertia (:func:`impedance_damping`).
    """
    return overlay_nm + stiffness * (q_cmd - q) + damping * (dq_cmd - dq)


def impedance_damping(stiffness: np.ndarray, ratio: float, inertia_diag: np.ndarray) -> np.ndarray:
    """(7,) [Nm s/rad] ``2 ratio sqrt(K m_jj)``: a damping ratio on each joint's own inertia ``m_jj``."""
    return 2.0 * ratio * np.sqrt(stiffness * np.maximum(inertia_diag, 0.0))


@dataclass
class FriCommand:
    """What the stack sends the robot in one FRI cycle: joint position (7,) [rad], torque overlay (7,) [Nm]."""

    joint_position: np.ndarray
    torque: np.ndarray


class StackError(RuntimeError):
    """The stack stops: it throws, or its hardware interface returns ERROR (the driver must be launched again)."""


@dataclass(slots=True)
class StackProcess:
    """The stack as a process: ``up`` while it runs (False once it exited: it publishes nothing more and the
    robot holds), ``exit_reason`` why it exited ("" while up), ``activated`` once its hardware interface is past
    on_activate (it publishes from then on)."""

    up: bool = True
    exit_reason: str = ""
    activated: bool = False


class CommandGuard:
    """The stack's ``default`` command guard (command_guard.cpp:7-64): the commanded joint position within the
    description's limits and the measured joint speed (position difference over the sample time) within its
    speed limits; the torque is not checked (the torque check, 66-79, is never called)."""

    def __init__(self, q_min: np.ndarray, q_max: np.ndarray, dq_max: np.ndarray) -> None:
        self.q_min, self.q_max, self.dq_max = q_min, q_max, dq_max
        self._q_prev: np.ndarray | None = None

    def invalid(self, q_command: np.ndarray, q_measured: np.ndarray, sample_time_s: float) -> str | None:
        bad = np.flatnonzero((q_command < self.q_min) | (q_command > self.q_max))
        if bad.size:
            i = int(bad[0])
            return f"commanded A{i + 1} {q_command[i]:+.3f} rad outside [{self.q_min[i]:+.3f}, {self.q_max[i]:+.3f}]"
        prev, self._q_prev = self._q_prev, np.array(q_measured, float)
        if prev is not None:
            over = np.flatnonzero(np.abs(q_measured - prev) / sample_time_s > self.dq_max)
            if over.size:
                i = int(over[0])
                return f"A{i + 1} moved {abs(q_measured[i] - prev[i]) / sample_time_s:.2f} rad/s > {self.dq_max[i]:.2f}"
        return None


class RobotSession:
    """The session the robot reports, over robot time [ns]: the operator starts the app, the overlay becomes
    active, the operator may stop the app, a poor link ends it.

    MONITORING_READY -(commanding_after_s)-> COMMANDING_WAIT -(commanding_wait_s)-> COMMANDING_ACTIVE
    -(stop_app_after_s, or :meth:`stop_app`)-> MONITORING_READY. A connection quality below GOOD for
    ``quality_abort_after_s`` ends commanding too, in MONITORING_WAIT while the quality stays below GOOD (the FRI
    SDK's friClientIf.h:72-86: MONITORING_WAIT is "monitoring mode with insufficient connection quality", FAIR
    "insufficient for command mode"; how soon the robot ends the overlay is not in any code read: a setting).
    """

    def __init__(self, p: LbrPeerParams) -> None:
        self.state = SessionState.MONITORING_READY
        self._wait_ns = round(p.commanding_after_s * 1e9)
        self._active_ns = self._wait_ns + round(p.commanding_wait_s * 1e9)
        self._stop_ns = round(p.stop_app_after_s * 1e9) if p.stop_app_after_s > 0 else None
        self._abort_ns = round(p.quality_abort_after_s * 1e9)
        self._low_since_ns: int | None = None  # robot time the quality fell below GOOD while commanding
        self.stopped = False

    def stop_app(self) -> None:
        """The operator ends the app (or a safety stop ends the motion): the overlay ends."""
        self.stopped = True

    def advance(self, t_ns: int, quality: int = ConnectionQuality.EXCELLENT) -> SessionState:
        if self.state == SessionState.COMMANDING_ACTIVE and quality < ConnectionQuality.GOOD:
            self._low_since_ns = t_ns if self._low_since_ns is None else self._low_since_ns
            if t_ns - self._low_since_ns >= self._abort_ns:
                self.stopped = True
        else:
            self._low_since_ns = None
        if self.stopped or (self._stop_ns is not None and t_ns >= self._stop_ns):
            self.stopped = True
            self.state = SessionState.MONITORING_WAIT if quality < ConnectionQuality.GOOD else \
                SessionState.MONITORING_READY
        elif t_ns >= self._active_ns:
            self.state = SessionState.COMMANDING_ACTIVE
        elif t_ns >= self._wait_ns:
            self.state = SessionState.COMMANDING_WAIT
        return self.state


class FriLink:
    """The FRI link between the robot and the stack's FRI thread, and the connection quality the robot reports.

    Lost from ``link_lost_at_s`` for ``link_lost_for_s`` (0: for good) of robot time: no packet either way. The
    stack opens its socket without a receive timeout (app.cpp:7, ``UdpConnection()``; the SDK's
    friUdpConnection.h:93-98: "0 = wait forever"), so its FRI thread waits in ``step()``
    (friClientApplication.cpp:118) and its state keeps the last values, time stamp included. The quality the robot
    reports falls one level (EXCELLENT, GOOD, FAIR, POOR) per ``quality_step_s``: from ``quality_drop_at_s`` (at
    which it is GOOD), and over an outage (GOOD after one step without answers); it is EXCELLENT again once the
    link is back. KUKA's own measure (latency, jitter, lost packets) is not in any code read: the ladder is a model.
    """

    def __init__(self, p: LbrPeerParams) -> None:
        self._lost_ns = round(p.link_lost_at_s * 1e9) if p.link_lost_at_s > 0 else None
        self._back_ns = self._lost_ns + round(p.link_lost_for_s * 1e9) if self._lost_ns is not None and \
            p.link_lost_for_s > 0 else None
        self._drop_ns = round(p.quality_drop_at_s * 1e9) if p.quality_drop_at_s > 0 else None
        self._step_ns = round(p.quality_step_s * 1e9)

    def up(self, t_ns: int) -> bool:
        """Whether the robot and the stack exchange packets at robot time ``t_ns``."""
        return self._lost_ns is None or t_ns < self._lost_ns or (self._back_ns is not None and t_ns >= self._back_ns)

    def quality(self, t_ns: int) -> ConnectionQuality:
        """The connection quality the robot reports at robot time ``t_ns``."""
        down = 0
        if self._drop_ns is not None and t_ns >= self._drop_ns:
            down = 1 + (t_ns - self._drop_ns) // self._step_ns
        if not self.up(t_ns) and self._lost_ns is not None:  # not up: the link is lost
            down = max(down, (t_ns - self._lost_ns) // self._step_ns)
        return ConnectionQuality(max(int(ConnectionQuality.EXCELLENT) - int(down), int(ConnectionQuality.POOR)))


def reported_commanded_torque(overlay_nm: np.ndarray, resolution_nm: float, offset_nm: float) -> np.ndarray:
    """(7,) [Nm] the ``commanded_torque`` the robot reports for the overlay (7,) it last commanded: rounded to
    ``resolution_nm`` (0: not rounded), plus ``offset_nm`` on every joint. The SDK documents ``getCommandedTorque()``
    only as "the last commanded joint torques of the robot" (friLBRState.h:204-209); the stack copies it
    (state.cpp:13-14). Whether the robot echoes the overlay bit for bit is not in any code read."""
    out = np.array(overlay_nm, float)
    if resolution_nm > 0:
        out = np.round(out / resolution_nm) * resolution_nm
    return out + offset_nm if offset_nm else out


@dataclass
class StackState:
    """The stack's state interface (what ``LBRState`` carries), SI units; ``q_rad`` is what it publishes as
    measured (the encoder, or its own command with ``open_loop``); the robot's time stamp [ns], sample time [s],
    connection quality and commanded torque (7,) [Nm] as the robot last reported them (state.cpp:13-15,30-33)."""

    q_rad: np.ndarray
    q_commanded_rad: np.ndarray
    tau_measured_nm: np.ndarray
    tau_external_nm: np.ndarray
    ipo_rad: np.ndarray
    session: SessionState
    stamp_ns: int = 0
    sample_time_s: float = 0.0
    connection_quality: int = int(ConnectionQuality.EXCELLENT)
    tau_commanded_nm: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))


class StackClient:
    """The stack between the robot (FRI, every cycle) and ROS (the controller manager, every ``cm_every``).

    FRI side, :meth:`fri_cycle` (async_client.cpp): in COMMANDING_WAIT the stack answers by itself with the
    measured position and zero torque (async_client.cpp:74-80, base_command.cpp:12-17); in COMMANDING_ACTIVE it
    runs :class:`JointPid` from its command target to the measured position (or, with ``open_loop``, to its own
    last command, which it then also publishes as measured: async_client.cpp:82-93, state.cpp:43-62) and sends
    the target's torque; a NaN target (no ROS command yet) is re-initialised to the measured position every
    cycle (torque_command.cpp:20-25); a robot not in the TORQUE client command mode makes it throw
    (torque_command.cpp:11-19). Each session change re-initialises the command (async_client.cpp:57-70).

    ROS side, :meth:`cm_cycle` (system_interface.cpp:291-354): read the state (leaving COMMANDING_ACTIVE makes
    read() return ERROR: :class:`StackError`), the torque command controller writes the last message it got into
    the command interfaces, every cycle, for as long as it runs (lbr_torque_command_controller.cpp:42-55), and
    write() hands them to the FRI side only while COMMANDING_ACTIVE.
    """

    def __init__(self, p: LbrPeerParams, q_min: np.ndarray, q_max: np.ndarray, dq_max: np.ndarray) -> None:
        self.p = p
        self.guard = CommandGuard(q_min, q_max, dq_max)
        self.command_mode = COMMAND_MODES[p.client_command_mode]
        self.pid = JointPid(p.pid_p, p.pid_i, p.pid_d, p.pid_i_max, p.pid_i_min)
        self.tau_measured = ExponentialFilter(p.measured_torque_cutoff_hz)
        self.tau_external = ExponentialFilter(p.external_torque_cutoff_hz)
        nan = np.full(N_JOINTS, np.nan)
        self.target = FriCommand(nan.copy(), nan.copy())  # the command target the FRI side uses
        self.command = FriCommand(np.zeros(N_JOINTS), np.zeros(N_JOINTS))  # what it last sent the robot
        self.hw_command = FriCommand(nan.copy(), nan.copy())  # ros2_control's command interfaces
        self.last_message: FriCommand | None = None  # the torque command controller's realtime buffer
        self.state = StackState(np.zeros(N_JOINTS), np.zeros(N_JOINTS), np.zeros(N_JOINTS), np.zeros(N_JOINTS),
                                np.zeros(N_JOINTS), SessionState.IDLE)
        self.hw_session = SessionState.IDLE
        self._session_prev: SessionState | None = None

    # -- the FRI side (every robot cycle) ------------------------------------------------------------------
    def fri_cycle(self, session: SessionState, q: np.ndarray, q_commanded: np.ndarray, tau_measured: np.ndarray,
                  tau_external: np.ndarray, robot_command_mode: int, sample_time_s: float, *, stamp_ns: int = 0,
                  connection_quality: int = ConnectionQuality.EXCELLENT,
                  tau_commanded: np.ndarray | None = None) -> FriCommand | None:
        """One FRI callback with the robot's state; the command sent back, or None (monitoring). The robot's time
        stamp [ns], connection quality and commanded torque (7,) [Nm] go into the state as they are."""
        st = self.state
        st.stamp_ns, st.sample_time_s, st.connection_quality = stamp_ns, sample_time_s, int(connection_quality)
        st.tau_commanded_nm = np.zeros(N_JOINTS) if tau_commanded is None else np.array(tau_commanded, float)
        if self._session_prev is not None and session != self._session_prev:
            self._set_state(session, q, q_commanded, tau_measured, tau_external, sample_time_s)
            self._init_command()
        self._session_prev = session
        if session == SessionState.COMMANDING_WAIT:
            self._set_state(session, q, q_commanded, tau_measured, tau_external, sample_time_s)
            self._init_command()
            return self._to_fri(robot_command_mode, sample_time_s)
        if session == SessionState.COMMANDING_ACTIVE:
            measured = self.command.joint_position.copy() if self.p.open_loop else q
            self._set_state(session, measured, q_commanded, tau_measured, tau_external, sample_time_s)
            return self._to_fri(robot_command_mode, sample_time_s)
        self._set_state(session, q, q_commanded, tau_measured, tau_external, sample_time_s)
        return None

    def _set_state(self, session, q, q_commanded, tau_measured, tau_external, sample_time_s) -> None:
        st = self.state
        st.session = session
        st.q_rad = np.array(q, float)
        st.q_commanded_rad = np.array(q_commanded, float)
        st.tau_measured_nm = self.tau_measured.update(tau_measured, sample_time_s).copy()
        st.tau_external_nm = self.tau_external.update(tau_external, sample_time_s).copy()
        if session in (SessionState.COMMANDING_WAIT, SessionState.COMMANDING_ACTIVE):
            st.ipo_rad = np.array(q_commanded, float)  # state.cpp:19-23: only while commanding

    def _init_command(self) -> None:
        self.target = FriCommand(self.state.q_rad.copy(), np.zeros(N_JOINTS))
        self.command = FriCommand(self.target.joint_position.copy(), self.target.torque.copy())

    def _to_fri(self, robot_command_mode: int, sample_time_s: float) -> FriCommand:
        if robot_command_mode != ClientCommandMode.TORQUE or self.command_mode != ClientCommandMode.TORQUE:
            raise StackError(f"the stack commands in {self.command_mode.name} mode, the robot is in "
                             f"{_name(robot_command_mode)}: the torque interface throws (torque_command.cpp:11-19)")
        if np.isnan(self.target.joint_position).any() or np.isnan(self.target.torque).any():
            self._init_command()
        self.pid.step(self.target.joint_position, self.state.q_rad, sample_time_s, self.command.joint_position)
        self.command.torque = self.target.torque.copy()
        why = self.guard.invalid(self.command.joint_position, self.state.q_rad, sample_time_s)
        if why is not None:
            raise StackError(f"Invalid command: {why} (command_guard.cpp, torque_command.cpp:40-46)")
        return FriCommand(self.command.joint_position.copy(), self.command.torque.copy())

    # -- the ROS side (every controller-manager cycle) -----------------------------------------------------
    def receive(self, joint_position: np.ndarray, torque: np.ndarray) -> None:
        """A torque command message reached the controller's subscription (depth 1: the newest wins)."""
        self.last_message = FriCommand(np.array(joint_position, float), np.array(torque, float))

    def cm_cycle(self) -> StackState:
        """read(), update(), write() of the controller manager; the state it publishes. StackError on leaving
        COMMANDING_ACTIVE (system_interface.cpp:307-318)."""
        session = self.state.session
        if self.hw_session == SessionState.COMMANDING_ACTIVE and session != SessionState.COMMANDING_ACTIVE:
            raise StackError("LBR left COMMANDING_ACTIVE. Please re-run lbr_bringup (system_interface.cpp:307-318)")
        self.hw_session = session
        if self.last_message is not None:  # re-applied every update while the controller runs
            self.hw_command = FriCommand(self.last_message.joint_position.copy(), self.last_message.torque.copy())
        if self.hw_session == SessionState.COMMANDING_ACTIVE:
            self.target = FriCommand(self.hw_command.joint_position.copy(), self.hw_command.torque.copy())
        return self.state


def estimated_wrench(jacobian_tip: np.ndarray, tau_external: np.ndarray, R_base_tip: np.ndarray, damping: float,
                     force_threshold_n: float, torque_threshold_nm: float, threshold_in_tip: bool) -> np.ndarray:
    """(6,) the stack's force-torque estimate [N, Nm] at the tip, tip axes (ft_estimator.cpp).

    ``f = pinv_damped(J^T) tau_ext`` with J (6, 7) the tip's Jacobian in base axes (linear rows first), then
    rotated into the tip frame (``R_base_tip``, (3, 3)); a soft deadband: a component below its threshold is 0,
    one above it loses the threshold (ft_estimator.hpp:26-28). ``rolling`` thresholds the base-axes components
    before the rotation (ft_estimator.cpp:16-24), ``humble`` the tip-axes ones after it (43-51):
    ``threshold_in_tip``.
    """
    J = jacobian_tip
    f = np.linalg.solve(J @ J.T + damping**2 * np.eye(6), J @ tau_external)
    th = np.array([force_threshold_n] * 3 + [torque_threshold_nm] * 3)
    if not threshold_in_tip:
        f = soft_threshold(f, th)
    out = np.concatenate([R_base_tip.T @ f[:3], R_base_tip.T @ f[3:]])
    return soft_threshold(out, th) if threshold_in_tip else out


def soft_threshold(x: np.ndarray, th: np.ndarray) -> np.ndarray:
    """``sign(x) max(|x| - th, 0)`` per component."""
    return np.sign(x) * np.maximum(np.abs(x) - th, 0.0)


def _name(value: int) -> str:
    try:
        return ClientCommandMode(value).name
    except ValueError:
        return f"unknown({value})"
