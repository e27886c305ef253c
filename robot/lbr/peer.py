"""The lbr peer: a robot to test against, speaking lbr_fri_ros2_stack's CDR on zenoh-bridge-ros2dds's keys.

It stands in for ROS 2 + ros2_control + KUKA FRI seen through the bridge,
backed by the PyBullet iiwa of :mod:`sim`. Our real-robot adapter talks to
it exactly as to the real stack. Keys (namespace ``lbr``, see
:class:`~robot.lbr.msgs.LbrTopics`):

* ``lbr/state`` (out, every FRI cycle): ``LBRState``, stamped with the
  simulated robot clock; measured_torque is what the joints exert,
  including the robot's own gravity compensation; external_torque is
  ``J(q)^T w`` of the contact wrench (the torques the environment exerts
  on the arm); commanded_* are the last command as received.
* ``lbr/force_torque_broadcaster/wrench`` (out, ``wrench_rate_hz`` of robot
  time): ``WrenchStamped`` with frame_id ``<robot>_link_ee`` whose numbers
  are the force [N] and torque [Nm] the environment exerts on the tool,
  *world-aligned axes* (robot base), torque about the TCP (the pad centre),
  not in the flange frame. (The stack's estimate, ``pinv(J^T) tau_ext``
  rotated by the tip orientation and thresholded, differs between
  versions; recompute it from external_torque if the frame matters.)
* ``lbr/joint_states`` (out, ``joint_states_rate_hz``): ``JointState``,
  names ``<robot>_A1`` .. ``<robot>_A7`` (``lbr_A1`` by default), positions.
* ``lbr/command/torque`` (in): ``LBRTorqueCommand`` (joint_position,
  torque). Undecodable, wrong-length or non-finite ones are dropped and
  counted by reason.

FRI session (:class:`FriSession`, robot time): MONITORING_READY until the
"operator" starts the LBRServer app (``commanding_after_s``), then
COMMANDING_WAIT; the first valid command makes it COMMANDING_ACTIVE. No
command for ``watchdog_s`` drops it to MONITORING_READY (a watchdog trip)
and COMMANDING_WAIT returns ``recommanding_after_s`` later. Only in
COMMANDING_ACTIVE is torque applied: the LBRServer app runs
JOINT_IMPEDANCE_CONTROL with torque overlay, ``tau = torque + K
(joint_position - q)`` plus the robot's own gravity compensation; for a
pure torque overlay the user sets the stiffness K to 0 on the pendant (our
default). Otherwise the brakes hold the arm.

Timing: real time steps every ``sample_time_s`` on wall-clock deadlines and
applies the newest command (zero-order hold); the watchdog counts robot
time since the last command. Lock-step publishes state k and, while
commanding is offered (COMMANDING_WAIT, COMMANDING_ACTIVE), steps once per
received valid command (``LBRTorqueCommand`` has no sequence number, so
any command answers the current state), re-publishing the current state
(same stamp) every ``republish_s`` while it waits; there the watchdog
counts the wall time spent waiting for an answer. In MONITORING_READY no
client can command, so the robot runs on its own clock at the FRI rate,
arm held, for exactly the robot time the session says (commanding_after_s,
recommanding_after_s): a run with a client that answers in time is
deterministic for a seed.

Under the lamps prefix the peer publishes what the plain sim does (through
:class:`sim.service.SimPort`): ``sim/truth``, camera frames, and its
``ServiceStatus`` on ``sim/status``. Its liveliness token is
``alive/lbr-peer``.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from interfaces.config import check_range, dataclass_from_table
from interfaces.errors import ConfigError
from interfaces.loop_stats import LoopStats
from interfaces.messages import ServiceStatus
from interfaces.robot_model import RobotModel
from interfaces.session import CONTROL_QOS, ServiceNode
from sim.core import SimCore
from sim.params import SimParams
from sim.service import SimPort

from .msgs import (CLIENT_COMMAND_MODE_TORQUE, CONTROL_MODE_JOINT_IMPEDANCE, N_JOINTS, DriveState, LbrState,
                   LbrTopics, LbrWireError, OperationMode, SafetyState, SessionState, decode_torque_command,
                   encode_joint_state, encode_state, encode_wrench)

log = logging.getLogger(__name__)

SERVICE = "lbr-peer"
MODES = ("lockstep", "realtime")
OPERATION_MODES = {"T1": OperationMode.TEST_MODE_1, "T2": OperationMode.TEST_MODE_2,
                   "AUT": OperationMode.AUTOMATIC_MODE}
#: A CDR LBRTorqueCommand: 4-byte encapsulation header, then two float64[7] (fixed arrays, no length field).
TORQUE_COMMAND_BYTES = 4 + 2 * N_JOINTS * 8
_NAMESPACE = re.compile(r"[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")
_LOG_PERIOD_S = 5.0


@dataclass(frozen=True)
class LbrPeerParams:
    """The ``[lbr_peer]`` table; the arm, board and camera come from ``[sim]`` (gravity compensated, forced).

    namespace : the stack's robot name (topics ``/<namespace>/...``); mode : ``lockstep`` | ``realtime``;
    sample_time_s : the FRI period [s]; watchdog_s : no command this long in COMMANDING_ACTIVE ends
    commanding [s]; commanding_after_s : robot time at which the operator has started the LBRServer app [s];
    recommanding_after_s : back to COMMANDING_WAIT this long after a watchdog trip [s];
    joint_stiffness_nm_rad : the app's joint impedance spring towards the commanded joint_position
    [Nm/rad] (0: pure torque overlay, as the user sets it on the real robot); wrench_rate_hz,
    joint_states_rate_hz : rates of robot time [Hz]; operation_mode : ``T1`` | ``T2`` | ``AUT`` (only
    reported); republish_s : lock-step re-send period of an unanswered state [s]; status_rate_hz : wall [Hz].
    """

    namespace: str = "lbr"
    mode: str = "lockstep"
    sample_time_s: float = 0.001
    watchdog_s: float = 0.1
    commanding_after_s: float = 0.0
    recommanding_after_s: float = 1.0
    joint_stiffness_nm_rad: float = 0.0
    wrench_rate_hz: float = 100.0
    joint_states_rate_hz: float = 100.0
    operation_mode: str = "T1"
    republish_s: float = 0.05
    status_rate_hz: float = 2.0

    def __post_init__(self) -> None:
        s = "lbr_peer"
        if not isinstance(self.namespace, str) or not _NAMESPACE.fullmatch(self.namespace.strip("/")):
            raise ConfigError(f"[{s}] namespace must be a ROS name like 'lbr' (letters, digits, '_', "
                              f"'/'-separated), got {self.namespace!r}")
        object.__setattr__(self, "namespace", self.namespace.strip("/"))
        if self.mode not in MODES:
            raise ConfigError(f"[{s}] mode must be one of {MODES}, got {self.mode!r}")
        if self.operation_mode not in OPERATION_MODES:
            raise ConfigError(f"[{s}] operation_mode must be one of {tuple(OPERATION_MODES)}, "
                              f"got {self.operation_mode!r}")
        check_range(s, "sample_time_s", self.sample_time_s, 0.001, 0.01)
        rate = 1.0 / self.sample_time_s
        check_range(s, "watchdog_s", self.watchdog_s, 2 * self.sample_time_s, 10.0)
        check_range(s, "commanding_after_s", self.commanding_after_s, 0.0, 3600.0)
        check_range(s, "recommanding_after_s", self.recommanding_after_s, 0.0, 3600.0)
        check_range(s, "joint_stiffness_nm_rad", self.joint_stiffness_nm_rad, 0.0, 5000.0)
        check_range(s, "wrench_rate_hz", self.wrench_rate_hz, 0.1, rate)
        check_range(s, "joint_states_rate_hz", self.joint_states_rate_hz, 0.1, rate)
        check_range(s, "republish_s", self.republish_s, 0.001, 10.0)
        check_range(s, "status_rate_hz", self.status_rate_hz, 0.1, 100.0)

    @property
    def topics(self) -> LbrTopics:
        return LbrTopics(self.namespace)

    @property
    def robot_name(self) -> str:
        """The prefix of the stack's joint and link names (the last chunk of the namespace)."""
        return self.namespace.split("/")[-1]

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> LbrPeerParams:
        return dataclass_from_table(cls, "lbr_peer", table)


def sim_params_for_peer(sim_table: Mapping[str, Any], p: LbrPeerParams) -> SimParams:
    """The ``[sim]`` table with what the peer decides: gravity compensated (the robot does it) and its mode. The
    physics keeps the sim's own step (1 ms by default); an FRI period of several steps holds each command over
    them, as the robot's own joint loop does (:func:`substeps_for_peer`)."""
    return SimParams.from_table({**sim_table, "gravity_compensated": True, "mode": p.mode})


def substeps_for_peer(sim: SimParams, p: LbrPeerParams) -> int:
    """Physics steps per FRI cycle; ConfigError unless the FRI period is a whole number of them."""
    n = p.sample_time_s * sim.rate_hz
    if abs(n - round(n)) > 1e-6 or round(n) < 1:
        raise ConfigError(f"[lbr_peer] sample_time_s = {p.sample_time_s} s must be a whole number of the sim's "
                          f"physics steps (1 / [sim] rate_hz = {1.0 / sim.rate_hz} s)")
    return int(round(n))


# -- the pure parts -------------------------------------------------------------------------------------


class FriSession:
    """FRI session states over robot time [ns]: the operator, the LBRServer app and the watchdog.

    MONITORING_READY -(t >= commanding_after_s)-> COMMANDING_WAIT -(valid command)-> COMMANDING_ACTIVE
    -(no command for more than watchdog_s: a trip)-> MONITORING_READY -(recommanding_after_s later)->
    COMMANDING_WAIT.
    """

    def __init__(self, p: LbrPeerParams) -> None:
        self.state = SessionState.MONITORING_READY
        self.watchdog_trips = 0
        self._wait_at_ns = _ns(p.commanding_after_s)
        self._watchdog_ns = _ns(p.watchdog_s)
        self._recommanding_ns = _ns(p.recommanding_after_s)
        self._last_command_ns = 0

    def command(self, t_ns: int) -> bool:
        """A valid command at robot time ``t_ns``; True when the session commands (the command is applied)."""
        if self.state == SessionState.COMMANDING_WAIT:
            self.state = SessionState.COMMANDING_ACTIVE
        if self.state == SessionState.COMMANDING_ACTIVE:
            self._last_command_ns = t_ns
            return True
        return False

    def advance(self, t_ns: int, waited_ns: int = 0) -> str | None:
        """The time-driven transitions at robot time ``t_ns``; the reason when the watchdog tripped, else None.

        The command's age is the robot time since the last command, or ``waited_ns`` when longer (lock-step:
        the wall time spent waiting for an answer, while robot time stands still).
        """
        if self.state == SessionState.MONITORING_READY and t_ns >= self._wait_at_ns:
            self.state = SessionState.COMMANDING_WAIT
        elif self.state == SessionState.COMMANDING_ACTIVE:
            age_ns = max(t_ns - self._last_command_ns, waited_ns)
            if age_ns > self._watchdog_ns:
                self.state = SessionState.MONITORING_READY
                self.watchdog_trips += 1
                self._wait_at_ns = t_ns + self._recommanding_ns
                return f"no torque command for {age_ns / 1e6:.0f} ms (watchdog {self._watchdog_ns / 1e6:.0f} ms)"
        return None


def _ns(seconds: float) -> int:
    return round(seconds * 1e9)


def applied_torque_nm(torque_nm: np.ndarray, q_commanded_rad: np.ndarray, q_rad: np.ndarray,
                      stiffness_nm_rad: float) -> np.ndarray:
    """Joint torques (7,) [Nm] of torque overlay on joint impedance: ``tau = torque + K (q_commanded - q)``.

    The robot adds its own gravity compensation on top (not part of this).
    """
    return torque_nm + stiffness_nm_rad * (q_commanded_rad - q_rad)


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


# -- the network edge -----------------------------------------------------------------------------------


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
    """The simulated arm behind the stack's keys. ``run()`` blocks until :attr:`stop` is set.

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
        self._cycles = 0  # FRI cycles (each of port.substeps physics steps)
        self.model = RobotModel()
        self.session = FriSession(params)
        self.counters: Counter[str] = Counter()
        self.stats = LoopStats()
        self.stop = threading.Event()
        self._lockstep = params.mode == "lockstep"
        topics, raw = params.topics, node.session
        self._pub_state = raw.declare_publisher(topics.key(topics.state), **CONTROL_QOS)  # the FRI packet: first
        self._pub_wrench = raw.declare_publisher(topics.key(topics.wrench))
        self._pub_joints = raw.declare_publisher(topics.key(topics.joint_states))
        self.commands = CommandBox(raw, topics.key(topics.torque_command), channel=not self._lockstep)
        self._active: tuple[np.ndarray, np.ndarray] | None = None  # the held command while commanding
        self._received: tuple[np.ndarray, np.ndarray] | None = None  # the last valid command, for the state
        self._wrench_every = max(round(1.0 / (params.sample_time_s * params.wrench_rate_hz)), 1)
        self._joints_every = max(round(1.0 / (params.sample_time_s * params.joint_states_rate_hz)), 1)
        self._joint_names = [f"{params.robot_name}_A{i}" for i in range(1, N_JOINTS + 1)]
        self._frame_id = f"{params.robot_name}_link_ee"
        self._zeros = np.zeros(N_JOINTS)
        self._state_bytes = b""
        self._status_period_s = 1.0 / params.status_rate_hz
        self._next_status = 0.0
        self._t_prev_ns = time.monotonic_ns()

    # -- lifecycle --------------------------------------------------------------------------------------
    def run(self) -> int:
        """Serve until stopped; returns the number of FRI cycles stepped."""
        try:
            self.port.activate()  # the camera renderer (RuntimeError if it does not come up)
            self.session.advance(self.core.time_ns)
            self._publish_outputs()
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

    # -- one FRI cycle ----------------------------------------------------------------------------------
    def cycle(self, command: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Take the newest valid command (or none), apply it or hold the arm, step once, publish."""
        if command is not None:
            self._received = command
            if self.session.command(self.core.time_ns):
                self._active = command
                self.counters["commands_applied"] += 1
            else:
                self.counters["commands_while_not_commanding"] += 1
        if self.session.state == SessionState.COMMANDING_ACTIVE:
            if command is None:
                self.counters["cycles_without_new_command"] += 1
            q_cmd, torque = self._active
            self.port.write(applied_torque_nm(torque, q_cmd, self.core.out.q, self.p.joint_stiffness_nm_rad))
        else:
            self.port.hold()
            self.counters["cycles_held"] += 1
        self._watchdog(0)
        self._cycles += 1
        self.port.after_cycle(self._lockstep and self.session.state != SessionState.MONITORING_READY)
        self._publish_outputs()

    def _publish_outputs(self) -> None:
        o, t_ns, k = self.core.out, self.core.time_ns, self._cycles
        q_cmd, torque = self._received if self._received is not None else (o.q, self._zeros)
        if np.any(o.wrench):
            tau_ext = external_torque_nm(self.model.tcp_jacobian(o.q), o.wrench)
        else:
            tau_ext = self._zeros  # free space: no Jacobian needed
        state = LbrState(
            sample_time_s=self.p.sample_time_s, session_state=int(self.session.state),
            safety_state=int(SafetyState.NORMAL_OPERATION), operation_mode=int(OPERATION_MODES[self.p.operation_mode]),
            drive_state=int(DriveState.ACTIVE), client_command_mode=CLIENT_COMMAND_MODE_TORQUE,
            control_mode=CONTROL_MODE_JOINT_IMPEDANCE, stamp_ns=t_ns, q_rad=o.q, tau_measured_nm=o.tau,
            tau_external_nm=tau_ext, q_commanded_rad=q_cmd)
        self._state_bytes = encode_state(state, commanded_torque_nm=torque)
        self._pub_state.put(self._state_bytes)
        if k % self._wrench_every == 0:
            self._pub_wrench.put(encode_wrench(self._frame_id, o.wrench, t_ns))
        if k % self._joints_every == 0:
            self._pub_joints.put(encode_joint_state(self._joint_names, o.q, t_ns))

    # -- loops ------------------------------------------------------------------------------------------
    def _run_realtime(self) -> None:
        # no SCHED_FIFO here (the loops of the controller and the adapter have it): the peer's loop is the
        # simulator, busy for most of each FRI period, and as a FIFO thread it starved the Zenoh threads of
        # every process on its core (a CI run: commands 100 ms late, the peer's FRI watchdog tripped)
        period_ns = _ns(self.p.sample_time_s)
        next_ns = time.monotonic_ns()
        while not self.stop.is_set():
            command, superseded = self.commands.newest()
            if superseded:
                self.counters["commands_superseded"] += superseded
            next_ns = self._paced_cycle(command, next_ns, period_ns)

    def _run_lockstep(self) -> None:
        """Wait for a command per cycle while commanding is offered; run on the robot's own clock otherwise."""
        period_ns = _ns(self.p.sample_time_s)
        next_ns: int | None = None  # the free-running clock's next deadline, while MONITORING_READY
        waiting_since = last_pub = time.monotonic_ns()
        t_prev = time.perf_counter_ns()
        while not self.stop.is_set():
            if self.session.state == SessionState.MONITORING_READY:  # no client can command: nothing to wait for
                command, superseded = self.commands.newest()
                if command is not None:
                    self.counters["commands_while_not_commanding"] += superseded + 1
                next_ns = self._paced_cycle(None, next_ns or time.monotonic_ns(), period_ns)
                waiting_since = last_pub = time.monotonic_ns()
                continue
            t0 = time.perf_counter_ns()
            command = self.commands.get(min(self.p.republish_s, self.p.watchdog_s / 4, 0.05))
            now = time.monotonic_ns()
            self._publish_status()
            if command is None:
                self._watchdog(now - waiting_since)
                if now - last_pub >= _ns(self.p.republish_s):
                    self._pub_state.put(self._state_bytes)  # the same state again: same stamp
                    self.counters["states_republished"] += 1
                    last_pub = now
                continue
            t1 = time.perf_counter_ns()
            self.cycle(command)
            t2 = time.perf_counter_ns()
            self.stats.add((t2 - t_prev) / 1e3, (t1 - t0) / 1e3, (t2 - t1) / 1e3, 0.0)
            t_prev = t2
            next_ns = None
            waiting_since = last_pub = time.monotonic_ns()

    def _paced_cycle(self, command, next_ns: int, period_ns: int) -> int:
        """One cycle on the wall clock: step, status, sleep until the next deadline (returned)."""
        t0 = time.monotonic_ns()
        self.cycle(command)
        t1 = time.monotonic_ns()
        self._publish_status()
        t2 = time.monotonic_ns()
        self.stats.add((t0 - self._t_prev_ns) / 1e3, 0.0, (t1 - t0) / 1e3, (t2 - t1) / 1e3)
        self._t_prev_ns = t0
        next_ns = self.stats.next_deadline(next_ns, period_ns, t2)
        time.sleep(max(next_ns - t2, 0) / 1e9)
        return next_ns

    def _watchdog(self, waited_ns: int) -> None:
        why = self.session.advance(self.core.time_ns, waited_ns)
        if why is not None:
            self._active = None
            log.warning("watchdog: %s; leaving COMMANDING_ACTIVE, the arm is held", why)

    # -- status -----------------------------------------------------------------------------------------
    def status(self) -> ServiceStatus:
        counters = dict(self.counters)
        counters.update(self.commands.counters())
        counters.update(self.port.counters())
        counters.update(watchdog_trips=self.session.watchdog_trips, session_state=int(self.session.state),
                        steps=self.core.steps)
        detail = (f"mode={self.p.mode} step={self.core.steps} session={self.session.state.name} "
                  f"namespace={self.p.namespace}")
        return ServiceStatus(service=SERVICE, seq=self.core.steps, stamp_ns=time.monotonic_ns(), counters=counters,
                             detail=detail, timing=self.stats.summary())

    def _publish_status(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._next_status:
            return
        self._next_status = now + self._status_period_s
        self.node.publish(self.node.keys.sim_status, self.status())
