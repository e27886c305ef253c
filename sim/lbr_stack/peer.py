"""The lbr peer: the PyBullet iiwa behind lbr_fri_ros2_stack's messages, behaving as the stack's code does.

A stand-in for the robot (the LBRServer app, FRI) and lbr_fri_ros2_stack
(its FRI client and ros2_control loop) seen through zenoh-bridge-ros2dds.
The real-robot adapter talks to it as to the real stack. Every behaviour
is the stack's (:mod:`sim.lbr_stack.stack`; the table with the stack's
files, lines and commits is docs/real-robot.md):

* **Nothing is published before COMMANDING_WAIT**: the stack's hardware
  interface waits for it in on_activate (system_interface.cpp:249-265).
* **The last command is re-applied for as long as the stack runs**
  (lbr_torque_command_controller.cpp:42-55), and the stack answers every
  FRI cycle itself (async_client.cpp:74-93): no FRI watchdog ever fires
  because a client went quiet. Before the first message the stack holds
  its command target at the measured position with zero torque
  (torque_command.cpp:20-25).
* **The robot holds a joint spring**: the app runs joint impedance at
  ``joint_stiffness_nm_rad`` (LBRServer.java: 200 on every joint), the
  torque overlay is added (``tau = overlay + K (q_cmd - q) + D (dq_cmd - dq)``
  plus the robot's gravity compensation), and ``q_cmd`` is the stack's PID
  output towards the message's ``joint_position`` (filters.cpp:56-62).
* **open_loop** (the stack's default: true) publishes the stack's own
  position command as measured (async_client.cpp:82-85, state.cpp:43-62).
* **Filtered torques**: measured and external torque low-passed at the
  configured cutoffs (state.cpp:18,26; filters.cpp:23-28).
* **FRI 1 or FRI 2 LBRState** (``fri_major``), joint names by ``branch``.
* **The stack exits** when the robot leaves COMMANDING_ACTIVE
  (system_interface.cpp:307-318), when the robot is not in the TORQUE
  client command mode (torque_command.cpp:11-19) and when its command guard
  fails (command_guard.cpp:7-64): it publishes nothing more and the robot
  holds; the driver must be launched again.
* **The wrench** (``force_torque_broadcaster/wrench``) is the stack's
  estimate at ``lbr_link_ee``, tip axes, soft deadband, ``ft_update_rate_hz``.
* **The controller manager** runs every ``cm_every`` FRI cycles
  (``update_rate_hz``): states are published at that rate and a message
  reaches the robot at the manager's next cycle.

Keys (namespace ``lbr``): ``lbr/state`` (LBRState), ``lbr/joint_states``,
``lbr/force_torque_broadcaster/wrench`` out; ``lbr/command/torque`` in
(undecodable, wrong-length or non-finite messages are dropped and counted
by reason: the bridge would not deliver them as LBRTorqueCommand).

Timing: real time runs the FRI period on wall-clock deadlines, the
controller manager taking the newest message at its cycle. Lock-step
publishes the state of a manager cycle, runs the FRI cycles that follow
with the message it had (a message reaches the robot one manager cycle
after the state it answers, as on the real stack), then waits up to
``lockstep_wait_s`` of wall time for the answer before the next manager
cycle; an answer that does not come is not waited for again: the robot
runs on re-applying the last message, paced on the wall clock. Before the
stack is active and after it has exited the robot runs on the wall clock.

Under the lamps prefix the peer publishes what the plain sim does (through
:class:`sim.service.SimPort`): ``sim/truth``, camera frames, and its
``ServiceStatus`` on ``sim/status``. Its liveliness token is
``alive/lbr-peer``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Mapping
from typing import Any

import numpy as np
import pinocchio as pin
import zenoh

from interfaces.errors import ConfigError
from interfaces.loop_stats import LoopStats
from interfaces.messages import HOLD, ServiceStatus
from interfaces.robot_model import RobotModel
from interfaces.session import CONTROL_QOS, ServiceNode
from robot.lbr.msgs import (N_JOINTS, DriveState, LbrState, LbrWireError, SafetyState, SessionState,
                            decode_torque_command, encode_joint_state, encode_state, encode_wrench)
from robot.lbr.tip import tip_jacobian, tip_pose
from sim.core import SimCore
from sim.params import SimParams
from sim.service import SimPort

from .params import COMMAND_MODES, CONTROL_MODES, OPERATION_MODES, LbrPeerParams
from .stack import (FriCommand, RobotSession, StackClient, StackError, estimated_wrench, impedance_damping,
                    joint_impedance_torque)

log = logging.getLogger(__name__)

SERVICE = "lbr-peer"
#: A CDR LBRTorqueCommand: 4-byte encapsulation header, then two float64[7] (fixed arrays, no length field).
TORQUE_COMMAND_BYTES = 4 + 2 * N_JOINTS * 8
_LOG_PERIOD_S = 5.0


def sim_params_for_peer(sim_table: Mapping[str, Any], p: LbrPeerParams) -> SimParams:
    """The ``[sim]`` table with what the peer decides: gravity compensated (the robot does it) and its mode. The
    physics keeps the sim's own step (1 ms by default); an FRI period of several steps runs the robot's joint
    impedance at every physics step with the FRI command held (:func:`substeps_for_peer`)."""
    return SimParams.from_table({**sim_table, "gravity_compensated": True, "mode": p.mode})


def substeps_for_peer(sim: SimParams, p: LbrPeerParams) -> int:
    """Physics steps per FRI cycle; ConfigError unless the FRI period is a whole number of them."""
    n = p.sample_time_s * sim.rate_hz
    if abs(n - round(n)) > 1e-6 or round(n) < 1:
        raise ConfigError(f"[lbr_peer] sample_time_s = {p.sample_time_s} s must be a whole number of the sim's "
                          f"physics steps (1 / [sim] rate_hz = {1.0 / sim.rate_hz} s)")
    return int(round(n))


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


def external_torque_nm(jacobian: np.ndarray, wrench: np.ndarray) -> np.ndarray:
    """``tau_ext = J^T w`` (7,) [Nm]: the joint torques of a wrench the environment exerts on the tool.

    jacobian : (6, 7) of the TCP, linear rows first, world-aligned axes; wrench : (6,) force [N] then
    torque about the TCP [Nm], world axes (virtual work: ``tau_ext . dq = w . J dq``).
    """
    return jacobian.T @ wrench


def drop_reason(raw: bytes, exc: LbrWireError) -> str:
    """Why a torque command was dropped: ``non_finite``, ``wrong_length``, ``not_cdr`` or ``malformed_cdr``."""
    text = str(exc)
    if "NaN" in text:
        return "non_finite"
    if "must hold" in text:
        return "wrong_length"
    if len(raw) < 4 or raw[0] != 0 or raw[1] > 0x0B:  # no CDR encapsulation header
        return "not_cdr"
    return "wrong_length" if len(raw) != TORQUE_COMMAND_BYTES else "malformed_cdr"  # fixed arrays: size = length


class CommandBox:
    """``LBRTorqueCommand`` samples of one key; bad ones counted by reason, dropped.

    Lock-step waits for the oldest with :meth:`get` (decoded in Zenoh's thread, handed over under a lock).
    Real time (``channel=True``) takes the newest with :meth:`newest`: Zenoh queues the raw samples in a ring
    of ``maxlen`` without Python, and the loop decodes them itself. A Python callback needs the GIL, which the
    simulator's step holds (PyBullet does not release it): with a busy loop a command could wait up to
    the interpreter's switch interval (5 ms) per sample, and they piled up (a 100 ms pile-up tripped the
    watchdog in a real-time run).
    """

    def __init__(self, session, key: str, maxlen: int = 64, channel: bool = False) -> None:
        self.key = key
        self.received = 0
        self.overflowed = 0
        self.dropped: Counter[str] = Counter()
        self._queue: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=maxlen)
        self._ready = threading.Condition()
        self._last_log = -float("inf")
        self._channel = channel
        if channel:
            self._sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(maxlen))
        else:
            self._sub = session.declare_subscriber(key, self._on_sample)

    def _decode(self, raw: bytes) -> tuple[np.ndarray, np.ndarray] | None:
        """The command in ``raw``, or None (counted by reason, logged at most every few seconds)."""
        try:
            return decode_torque_command(raw)
        except LbrWireError as exc:
            with self._ready:
                self.received += 1
                self.dropped[drop_reason(raw, exc)] += 1
            now = time.monotonic()
            if now - self._last_log >= _LOG_PERIOD_S:
                self._last_log = now
                log.warning("dropped a torque command on %s (%d so far): %s", self.key,
                            sum(self.dropped.values()), exc)
            return None

    def _on_sample(self, sample) -> None:
        command = self._decode(sample.payload.to_bytes())
        if command is None:
            return
        with self._ready:
            self.received += 1
            if len(self._queue) == self._queue.maxlen:
                self.overflowed += 1
            self._queue.append(command)
            self._ready.notify()

    def get(self, timeout_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The oldest valid command not yet taken, waiting up to ``timeout_s``; None on timeout (lock-step)."""
        if self._channel:
            raise RuntimeError("CommandBox.get needs the callback box (channel=False)")
        with self._ready:
            if not self._queue and not self._ready.wait_for(lambda: bool(self._queue), timeout_s):
                return None
            return self._queue.popleft()

    def newest(self) -> tuple[tuple[np.ndarray, np.ndarray] | None, int]:
        """(the newest valid command or None, how many older valid ones it superseded); never blocks."""
        if self._channel:
            newest, valid = None, 0
            while (sample := self._sub.try_recv()) is not None:
                command = self._decode(sample.payload.to_bytes())
                if command is not None:
                    newest, valid = command, valid + 1
            with self._ready:
                self.received += valid
            return newest, max(valid - 1, 0)
        with self._ready:
            if not self._queue:
                return None, 0
            command, superseded = self._queue[-1], len(self._queue) - 1
            self._queue.clear()
            return command, superseded

    def counters(self) -> dict[str, int]:
        with self._ready:
            out = {"commands_received": self.received, "commands_overflowed": self.overflowed}
            out.update({f"commands_dropped_{reason}": n for reason, n in self.dropped.items()})
        return out

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None


# -- the peer -------------------------------------------------------------------------------------------


class LbrPeer:
    """The simulated robot and stack behind the bridge's keys. ``run()`` blocks until :attr:`stop` is set.

    Parameters
    ----------
    params : the ``[lbr_peer]`` table. sim_params : from :func:`sim_params_for_peer`.
    node : an open :class:`ServiceNode` (its raw session carries the bridge keys).
    core : a built :class:`SimCore` of ``sim_params`` (built here if None).
    """

    def __init__(self, params: LbrPeerParams, sim_params: SimParams, node: ServiceNode,
                 core: SimCore | None = None) -> None:
        self.p = params
        self.node = node
        self.core = core or SimCore(sim_params)
        self.port = SimPort(sim_params, node, self.core, substeps_for_peer(sim_params, params))
        self.model = RobotModel(joints=self.core.joints)  # the simulated drives' rotor inertia in M
        lim = self.model.limits
        self.stack = StackClient(params, lim.q_min, lim.q_max, lim.dq_max)
        self.session = RobotSession(params)
        self.stack_up = True
        self.stack_exit = ""
        self.activated = False  # the stack's hardware interface is past on_activate: it publishes
        self.counters: Counter[str] = Counter()
        self.stats = LoopStats()
        self.stop = threading.Event()
        self._lockstep = params.mode == "lockstep"
        self._dt = params.sample_time_s
        self._cycles = 0  # FRI cycles
        self._stiffness = np.full(N_JOINTS, params.joint_stiffness_nm_rad)
        self._command_mode = int(COMMAND_MODES[params.client_command_mode])
        self._control_mode = int(CONTROL_MODES[params.control_mode])
        self._robot_command: FriCommand | None = None  # what the robot got in the last commanding cycle
        self.spring_max_nm = 0.0  # the largest joint spring torque K |q_cmd - q| the robot applied [Nm]
        self._ft_every = max(round(1.0 / (self._dt * params.ft_update_rate_hz)), 1)
        self._joints_every = max(round(1.0 / (self._dt * params.joint_states_rate_hz)), 1)
        self._wrench_tip = np.zeros(6)
        self._frame_id = f"{params.robot_name}/link_ee" if params.branch == "humble" else \
            f"{params.robot_name}_link_ee"
        topics, raw = params.topics, node.session
        self._pub_state = raw.declare_publisher(topics.key(topics.state), **CONTROL_QOS)
        self._pub_wrench = raw.declare_publisher(topics.key(topics.wrench))
        self._pub_joints = raw.declare_publisher(topics.key(topics.joint_states))
        self.commands = CommandBox(raw, topics.key(topics.torque_command), channel=not self._lockstep)
        self._zeros = np.zeros(N_JOINTS)
        self._state_bytes = b""
        self._status_period_s = 1.0 / params.status_rate_hz
        self._next_status = 0.0
        self._t_prev_ns = time.monotonic_ns()

    # -- lifecycle --------------------------------------------------------------------------------------
    def run(self) -> int:
        """Serve until stopped; returns the number of physics steps taken."""
        try:
            self.port.activate()  # the camera renderer (RuntimeError if it does not come up)
            if self._lockstep:
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            self._publish_status(force=True)
            self.close()
        return self.core.steps

    def close(self) -> None:
        self.commands.close()
        for pub in (self._pub_state, self._pub_wrench, self._pub_joints):
            pub.undeclare()
        self.port.close()

    def stop_app(self) -> None:
        """The operator stops the LBRServer app: the robot leaves COMMANDING_ACTIVE (and the stack exits)."""
        self.session.stop_app()

    # -- one FRI cycle (robot time advances by the FRI period) ------------------------------------------
    def fri_cycle(self) -> None:
        """The robot's cycle: the session, the stack's FRI answer, the robot's joint impedance over the physics
        steps of one FRI period (or the arm held), the robot's extras."""
        core, o = self.core, self.core.out
        session = self.session.advance(core.time_ns)
        command = None
        if self.stack_up:
            q_commanded = self._robot_command.joint_position if self._robot_command is not None else o.q
            try:
                command = self.stack.fri_cycle(session, o.q, q_commanded, o.tau, self._external_torque(),
                                               self._command_mode, self._dt)
            except StackError as exc:
                self._exit(str(exc))
        if command is not None and session == SessionState.COMMANDING_ACTIVE and \
                self._control_mode == CONTROL_MODES["joint_impedance"]:
            prev = self._robot_command
            dq_cmd = (command.joint_position - prev.joint_position) / self._dt if prev is not None else self._zeros
            self._robot_command = command
            damping = impedance_damping(self._stiffness, self.p.joint_damping_ratio, self._inertia_diag(o.q))
            for _ in range(self.port.substeps):
                core.step(joint_impedance_torque(command.torque, command.joint_position, dq_cmd, o.q, o.dq,
                                                 self._stiffness, damping))
            self.counters["cycles_commanding"] += 1
            spring = float(np.max(np.abs(self._stiffness * (command.joint_position - o.q))))
            self.spring_max_nm = max(self.spring_max_nm, spring)
        else:
            self._robot_command = None
            for _ in range(self.port.substeps):
                core.step(HOLD)
            self.counters["cycles_held"] += 1
        self._cycles += 1
        if self.stack_up and self.activated and self._cycles % self._ft_every == 0:
            self._update_wrench()
        self.port.after_cycle(self._lockstep and self.stack_up and self.activated)

    def cm_cycle(self, message: tuple[np.ndarray, np.ndarray] | None) -> None:
        """The controller manager's cycle: a new message to the torque controller (or None), read, update,
        write, and the broadcasters publish (once the stack is active)."""
        if not self.stack_up:
            return
        if message is not None:
            self.stack.receive(*message)
            self.counters["commands_received_by_controller"] += 1
        if not self.activated:
            if self.stack.state.session < SessionState.COMMANDING_WAIT:
                return  # still in on_activate: nothing is published
            self.activated = True
            log.info("the stack is active (session %s): publishing", self.stack.state.session.name)
        try:
            self.stack.cm_cycle()
        except StackError as exc:
            self._exit(str(exc))
            return
        self._publish_outputs()

    def _exit(self, reason: str) -> None:
        if self.stack_up:
            self.stack_up = False
            self.stack_exit = reason
            self.counters["stack_exits"] += 1
            log.warning("the stack exited: %s; the robot holds, nothing more is published", reason)

    # -- pieces -----------------------------------------------------------------------------------------
    def _external_torque(self) -> np.ndarray:
        o = self.core.out
        if np.any(o.wrench):
            return external_torque_nm(self.model.tcp_jacobian(o.q), o.wrench)
        return self._zeros  # free space: no Jacobian needed

    def _inertia_diag(self, q: np.ndarray) -> np.ndarray:
        return np.diag(pin.crba(self.model.model, self.model.data, q)).copy()

    def _update_wrench(self) -> None:
        q = self.stack.state.q_rad
        _, R = tip_pose(self.model, q)
        p = self.p
        self._wrench_tip = estimated_wrench(tip_jacobian(self.model, q), self.stack.state.tau_external_nm, R,
                                            p.ft_damping, p.ft_force_threshold_n, p.ft_torque_threshold_nm,
                                            threshold_in_tip=p.branch == "humble")

    def _publish_outputs(self) -> None:
        st, t_ns, k = self.stack.state, self.core.time_ns, self._cycles
        cmd = self._robot_command
        state = LbrState(
            sample_time_s=self._dt, session_state=int(st.session), safety_state=int(SafetyState.NORMAL_OPERATION),
            operation_mode=int(OPERATION_MODES[self.p.operation_mode]), drive_state=int(DriveState.ACTIVE),
            client_command_mode=self._command_mode, control_mode=self._control_mode, stamp_ns=t_ns,
            q_rad=st.q_rad, tau_measured_nm=st.tau_measured_nm, tau_external_nm=st.tau_external_nm,
            q_commanded_rad=st.q_commanded_rad)
        self._state_bytes = encode_state(state, commanded_torque_nm=cmd.torque if cmd is not None else self._zeros,
                                         fri_major=self.p.fri_major, ipo_joint_position_rad=st.ipo_rad)
        self._pub_state.put(self._state_bytes)
        self.counters["states_published"] += 1
        if k % self._ft_every < self.p.cm_every:
            self._pub_wrench.put(encode_wrench(self._frame_id, self._wrench_tip, t_ns))
        if k % self._joints_every < self.p.cm_every:
            self._pub_joints.put(encode_joint_state(self.p.joint_names, st.q_rad, t_ns))

    # -- loops ------------------------------------------------------------------------------------------
    def _run_realtime(self) -> None:
        # no SCHED_FIFO here: the peer's loop is the simulator, busy for most of each FRI period, and as a FIFO
        # thread it starved the Zenoh threads of every process on its core
        period_ns = _ns(self._dt)
        next_ns = time.monotonic_ns()
        while not self.stop.is_set():
            next_ns = self._paced(next_ns, period_ns, take_newest=True)

    def _paced(self, next_ns: int, period_ns: int, take_newest: bool) -> int:
        """One FRI period on the wall clock (a manager cycle first when one is due); the next deadline."""
        t0 = time.monotonic_ns()
        if self._cycles % self.p.cm_every == 0:
            message = None
            if take_newest:
                message, superseded = self.commands.newest()
                self.counters["commands_superseded"] += superseded
            self.cm_cycle(message)
        self.fri_cycle()
        t1 = time.monotonic_ns()
        self._publish_status()
        t2 = time.monotonic_ns()
        self.stats.add((t0 - self._t_prev_ns) / 1e3, 0.0, (t1 - t0) / 1e3, (t2 - t1) / 1e3)
        self._t_prev_ns = t0
        next_ns = self.stats.next_deadline(next_ns, period_ns, t2)
        time.sleep(max(next_ns - t2, 0) / 1e9)
        return next_ns

    def _run_lockstep(self) -> None:
        """Manager cycle (publish), the FRI cycles after it, then wait for the answer; the wall clock otherwise."""
        period_ns = _ns(self._dt)
        next_ns: int | None = None
        message = None
        running_on = False  # an answer did not come: the robot runs on its clock until one does
        while not self.stop.is_set():
            if not (self.stack_up and self.activated):  # nobody can answer: the robot runs on its own clock
                next_ns = self._paced(next_ns or time.monotonic_ns(), period_ns, take_newest=True)
                continue
            t0 = time.perf_counter_ns()
            self.cm_cycle(message)
            for _ in range(self.p.cm_every):
                self.fri_cycle()
            t1 = time.perf_counter_ns()
            wait_s = self._dt * self.p.cm_every if running_on else self.p.lockstep_wait_s
            message = self._wait_answer(wait_s)
            t2 = time.perf_counter_ns()
            self.stats.add((t2 - t0) / 1e3, (t2 - t1) / 1e3, (t1 - t0) / 1e3, 0.0)
            if message is None and not running_on and not self.stop.is_set():
                self.counters["lockstep_answers_missed"] += 1
                log.warning("no answer within %.3f s: the robot runs on, re-applying the last message",
                            self.p.lockstep_wait_s)
            running_on = message is None

    def _wait_answer(self, wait_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The answer to the published state, re-sending it every ``republish_s``; None after ``wait_s``."""
        deadline = time.monotonic() + wait_s
        while not self.stop.is_set():
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            command = self.commands.get(min(self.p.republish_s, left))
            self._publish_status()
            if command is not None:
                return command
            if self._state_bytes and time.monotonic() < deadline - 1e-3:
                self._pub_state.put(self._state_bytes)  # the same state again: same stamp
                self.counters["states_republished"] += 1
        return None

    # -- status -----------------------------------------------------------------------------------------
    def status(self) -> ServiceStatus:
        counters = dict(self.counters)
        counters.update(self.commands.counters())
        counters.update(self.port.counters())
        counters.update(session_state=int(self.session.state), steps=self.core.steps,
                        stack_up=int(self.stack_up), spring_max_mnm=round(self.spring_max_nm * 1e3))
        detail = (f"mode={self.p.mode} step={self.core.steps} session={self.session.state.name} "
                  f"namespace={self.p.namespace} fri={self.p.fri_major} branch={self.p.branch} "
                  f"open_loop={self.p.open_loop}" + (f" stack exited: {self.stack_exit[:120]}" if not self.stack_up
                                                     else ""))
        return ServiceStatus(service=SERVICE, seq=self.core.steps, stamp_ns=time.monotonic_ns(), counters=counters,
                             detail=detail, timing=self.stats.summary())

    def _publish_status(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._next_status:
            return
        self._next_status = now + self._status_period_s
        self.node.publish(self.node.keys.sim_status, self.status())
