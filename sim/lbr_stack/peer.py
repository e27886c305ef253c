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
* **The controller manager** runs at ``update_rate_hz``: in real time on
  its own clock (``manager_clock = "own"``, drifting ``manager_drift_ppm``
  against the robot's), as the real one does, so a state is published
  twice or skipped against FRI cycles; locked to every ``cm_every``-th FRI
  cycle in lock-step (or with ``manager_clock = "fri"``). A message reaches
  the robot at the FRI cycle after the manager's next cycle.
* **A lost FRI link** (``link_lost_at_s``, ``link_lost_for_s``): no packet
  either way. The stack's FRI socket has no receive timeout (app.cpp:7,
  friUdpConnection.h:93-98), so its FRI thread waits while the manager
  re-publishes the last state, time stamp and COMMANDING_ACTIVE included
  (system_interface.cpp:291-297); the messages the manager takes wait in
  its command buffer. The robot keeps its last command meanwhile (assumed)
  and its connection quality falls; when the link is back the stack applies
  the newest message.
* **The connection quality** (``quality_drop_at_s``, ``quality_step_s``)
  falls EXCELLENT, GOOD, FAIR, POOR; below GOOD for
  ``quality_abort_after_s`` the robot ends commanding (MONITORING_WAIT) and
  the stack exits.
* **The joint damping law** (``joint_damping_law``): ``D (dq_cmd - dq)``
  or ``-D dq`` (robot/lbr/release.py: the hold a dead adapter leaves is
  stable under the first only). **The tool's load data**
  (``tool_load_error_kg``): the mass it leaves out weighs on the arm and
  shows in the external torque.
* **The release** (``joint_position`` NaN): the stack re-initialises its
  command at the measured pose every cycle (torque_command.cpp:20-25).
* **commanded_torque** is the robot's last command, rounded to
  ``commanded_torque_resolution_nm`` and biased by
  ``commanded_torque_offset_nm`` when those are set (a robot that does not
  echo the overlay exactly).

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
runs on re-applying the last message, paced on the wall clock, as it does
until the first answer. Before the stack is active and after it has exited
the robot runs on the wall clock.

Under the lamps prefix the peer publishes what the plain sim does (through
:class:`sim.service.SimPort`): ``sim/truth``, camera frames, and its
``ServiceStatus`` on ``sim/status``. Its liveliness token is
``alive/lbr-peer``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Mapping
from typing import Any

import numpy as np

from interfaces.errors import ConfigError
from interfaces.messages import ServiceStatus
from robot.lbr.msgs import SessionState
from runtime.loop_stats import LoopStats
from runtime.session import ServiceNode
from sim.core import SimCore
from sim.params import SimParams
from sim.service import SimPort

from .broadcast import Broadcasters
from .commands import CommandBox
from .fri_robot import FriRobot
from .params import CONTROL_MODES, LbrPeerParams
from .stack import FriLink, RobotSession, StackClient, StackError, StackProcess

log = logging.getLogger(__name__)

SERVICE = "lbr-peer"


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


def next_manager_deadline(deadline_ns: int, period_ns: int, now_ns: int) -> tuple[int, int]:
    """(the manager's deadline after ``deadline_ns``, the periods it missed): missed ones are skipped (as
    ros2_control's loop sleeps to its next period), not caught up."""
    deadline_ns += period_ns
    missed = 0
    if now_ns > deadline_ns:
        missed = (now_ns - deadline_ns) // period_ns + 1
        deadline_ns += missed * period_ns
    return deadline_ns, int(missed)


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
        self.robot = FriRobot(params, self.core, self.port.substeps)
        lim = self.robot.model.limits
        self.stack = StackClient(params, lim.q_min, lim.q_max, lim.dq_max)
        self.session = RobotSession(params)
        self.link = FriLink(params)
        self.process = StackProcess()
        self.counters: Counter[str] = Counter()
        self.stats = LoopStats()
        self.stop = threading.Event()
        self._lockstep = params.mode == "lockstep"
        self._dt = params.sample_time_s
        self._cycles = 0  # FRI cycles
        self.outputs = Broadcasters(params, node.session, self.counters, self.robot.model, self.robot.command_mode,
                                    self.robot.control_mode)
        self.commands = CommandBox(node.session, params.topics.key(params.topics.torque_command),
                                   channel=not self._lockstep)
        self._status_period_s = 1.0 / params.status_rate_hz
        self._next_status = 0.0
        self._t_prev_ns = time.monotonic_ns()

    @property
    def stack_exit(self) -> str:
        """Why the stack exited ("" while it runs)."""
        return self.process.exit_reason

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
        self.outputs.close()
        self.port.close()

    def stop_app(self) -> None:
        """The operator stops the LBRServer app: the robot leaves COMMANDING_ACTIVE (and the stack exits)."""
        self.session.stop_app()

    # -- one FRI cycle (robot time advances by the FRI period) ------------------------------------------
    def fri_cycle(self) -> None:
        """The robot's cycle: the session, the stack's FRI answer, the robot's joint impedance over the physics
        steps of one FRI period (or the arm held), the robot's extras. While the link is lost the stack's FRI side
        does not run and the robot keeps its last command."""
        core, robot, proc = self.core, self.robot, self.process
        o = core.out
        t_ns = core.time_ns
        quality = self.link.quality(t_ns)
        session = self.session.advance(t_ns, quality)
        command = None
        if proc.up and self.link.up(t_ns):
            last = robot.command
            q_commanded = last.joint_position if last is not None else o.q
            reported = robot.reported_torque()
            try:
                command = self.stack.fri_cycle(session, o.q, q_commanded, o.tau, robot.external_torque(),
                                               robot.command_mode, self._dt, stamp_ns=t_ns,
                                               connection_quality=quality, tau_commanded=reported)
            except StackError as exc:
                self._exit(str(exc))
        elif proc.up:
            command = robot.command  # no packet: the robot keeps the last command it got (assumed)
            self.counters["fri_cycles_link_lost"] += 1
        if command is not None and session == SessionState.COMMANDING_ACTIVE and \
                robot.control_mode == CONTROL_MODES["joint_impedance"]:
            robot.apply(command)
            self.counters["cycles_commanding"] += 1
        else:
            robot.hold()
            self.counters["cycles_held"] += 1
        self._cycles += 1
        if proc.up and proc.activated and self._cycles % self.outputs.ft_every_fri == 0:
            self.outputs.update_wrench(self.stack.state)
        self.port.after_cycle(self._lockstep and proc.up and proc.activated)

    def cm_cycle(self, message: tuple[np.ndarray, np.ndarray] | None) -> None:
        """The controller manager's cycle: a new message to the torque controller (or None), read, update,
        write, and the broadcasters publish (once the stack is active)."""
        proc = self.process
        if not proc.up:
            return
        if message is not None:
            self.stack.receive(*message)
            self.counters["commands_received_by_controller"] += 1
        if not proc.activated:
            if self.stack.state.session < SessionState.COMMANDING_WAIT:
                return  # still in on_activate: nothing is published
            proc.activated = True
            log.info("the stack is active (session %s): publishing", self.stack.state.session.name)
        try:
            self.stack.cm_cycle()
        except StackError as exc:
            self._exit(str(exc))
            return
        self.outputs.publish(self.stack.state)

    def _exit(self, reason: str) -> None:
        proc = self.process
        if proc.up:
            proc.up = False
            proc.exit_reason = reason
            self.counters["stack_exits"] += 1
            log.warning("the stack exited: %s; the robot holds, nothing more is published", reason)

    # -- loops ------------------------------------------------------------------------------------------
    def _run_realtime(self) -> None:
        # no SCHED_FIFO here: the peer's loop is the simulator, busy for most of each FRI period, and as a FIFO
        # thread it starved the Zenoh threads of every process on its core
        if self.p.manager_clock == "own":
            self._run_own_clock()
            return
        period_ns = _ns(self._dt)
        next_ns = time.monotonic_ns()
        while not self.stop.is_set():
            next_ns = self._paced(next_ns, period_ns, take_newest=True)

    def _run_own_clock(self) -> None:
        """Real time with the controller manager on its own clock: the robot's FRI cycle and the manager's cycle
        each on their own wall-clock deadlines (the manager's period longer by ``manager_drift_ppm``, half a period
        out of phase). When both are due the robot's cycle runs first; missed deadlines are skipped, not caught
        up (the manager's counted in ``manager_overruns``)."""
        fri_ns = _ns(self._dt)
        cm_ns = _ns((1.0 + self.p.manager_drift_ppm * 1e-6) / self.p.update_rate_hz)
        next_fri = time.monotonic_ns()
        next_cm = next_fri + cm_ns // 2
        while not self.stop.is_set():
            t0 = time.monotonic_ns()
            if t0 >= next_fri:
                self.fri_cycle()
                t1 = time.monotonic_ns()
                self.stats.add((t0 - self._t_prev_ns) / 1e3, 0.0, (t1 - t0) / 1e3, 0.0)
                self._t_prev_ns = t0
                next_fri = self.stats.next_deadline(next_fri, fri_ns, t1)
            if time.monotonic_ns() >= next_cm:
                message, superseded = self.commands.newest()
                self.counters["commands_superseded"] += superseded
                self.cm_cycle(message)
                next_cm, missed = next_manager_deadline(next_cm, cm_ns, time.monotonic_ns())
                self.counters["manager_overruns"] += missed
            self._publish_status()
            time.sleep(max(min(next_fri, next_cm) - time.monotonic_ns(), 0) / 1e9)

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
        # an answer did not come: the robot runs on its clock until one does; none has come before the first (an
        # adapter arms on a robot whose clock it has seen advance, and sends nothing before)
        running_on = True
        while not self.stop.is_set():
            if not (self.process.up and self.process.activated):  # nobody can answer: the robot runs on its own clock
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
            if self.outputs.state_bytes and time.monotonic() < deadline - 1e-3:
                self.outputs.republish_state()  # the same state again: same stamp
        return None

    # -- status -----------------------------------------------------------------------------------------
    def status(self) -> ServiceStatus:
        counters = dict(self.counters)
        counters.update(self.commands.counters())
        counters.update(self.port.counters())
        counters.update(session_state=int(self.session.state), steps=self.core.steps,
                        stack_up=int(self.process.up), spring_max_mnm=round(self.robot.spring_max_nm * 1e3))
        t_ns = self.core.time_ns
        link = "" if self.link.up(t_ns) else " link=lost"
        manager = "fri" if self._lockstep else self.p.manager_clock
        detail = (f"mode={self.p.mode} step={self.core.steps} session={self.session.state.name} "
                  f"quality={self.link.quality(t_ns).name}{link} manager={manager} "
                  f"namespace={self.p.namespace} fri={self.p.fri_major} branch={self.p.branch} "
                  f"open_loop={self.p.open_loop}" + (f" stack exited: {self.stack_exit[:120]}" if not self.process.up
                                                     else ""))
        return ServiceStatus(service=SERVICE, seq=self.core.steps, stamp_ns=time.monotonic_ns(), counters=counters,
                             detail=detail, timing=self.stats.summary())

    def _publish_status(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._next_status:
            return
        self._next_status = now + self._status_period_s
        self.node.publish(self.node.keys.sim_status, self.status())
