"""The ``robot/*`` protocol, owned here once for every robot side: states out, commands in, timing, safety.

:class:`RobotServer` serves one :class:`~robot.port.RobotPort` on the
network. It publishes ``robot/state`` (:class:`~interfaces.messages.RobotState`)
and reads ``robot/command`` (:class:`~interfaces.messages.TorqueCommand`):

* lock-step (stepped ports): state k is published; the port is written
  once a valid command with ``seq == k`` arrives (state k is re-sent every
  ``republish_s`` until then), so a run is deterministic for a seed;
* real-time (stepped ports): ``rate_hz`` on absolute wall-clock deadlines,
  the newest command is held; with no command yet, a ``hold`` command, or
  a command older than ``stale_limit_s``, the port brakes and holds.
  An answer to a state older than ``stale_limit_s``, or, once the port has
  braked, to a state from before the brake, is dropped and counted: it was
  computed for an arm still moving (its damping of that motion drives the
  stopped arm back). Overruns are counted and the missed periods skipped,
  never caught up;
* clocked ports (a real robot): each new reading is published as it comes;
  each command answering the newest state is written as soon as it arrives;
  a state left unanswered when the next one comes is a late command, and
  the port holds that cycle; a state unanswered for ``stale_limit_s`` holds
  until one comes. With ``mode = "lockstep"`` the robot itself waits for
  each answer (the lbr peer's lock-step): no deadline, the unanswered state
  is re-sent every ``republish_s``.

The robot side holds the arm to limits of its own whatever is commanded
(:class:`~robot.guard.RobotGuard`, thresholds in :class:`ServerParams`,
stated in docs/security.md): a joint faster than ``speed_brake_share`` of its
limit (ports that declare ``velocity_limits_rad_s``), the pad faster than
that share of ``tool_speed_limit_m_s``, or pressing into the surface it
last touched faster than that share of ``press_speed_limit_m_s`` (ports that
declare a ``limits_model``), now, by its trend or under the command about to
be applied, brakes every joint until all are back under
``speed_release_share``; a contact force over ``force_cap_n`` (or about to
be) yields (gravity compensated, damped, no task torque:
:meth:`RobotPort.yield_hold`) until it is under ``force_release_share`` of the
cap. Each episode is counted (``joint_speed_brakes``, ``tool_speed_brakes``,
``press_speed_brakes``, ``contact_force_yields``) and logged. After any cycle
that applied none of the controller's torques the gate's rate limit counts
from what the arm ran on (:meth:`RobotPort.held_torque_nm`; the torques last
applied when the port cannot tell), so a brake ends with the torque climbing
back at the rate limit, not with a jump to a command that went on while it
held (``contact_tau_rate_nm_s`` while the pad touches). A controller that
keeps running into these limits (``fault_episodes`` within
``fault_window_s``) latches a FAULT-hold: every cycle holds, whatever is
commanded, until the operator's e-stop release; the state says ``estop``
meanwhile (the controller follows it), the status names it
(``guard=FAULT``, ``guard_faults``, ``guard_fault_latched``).

The e-stop is the robot side's too: an engaging :class:`~interfaces.messages.Estop`
on ``controller/estop`` makes every cycle a hold (:meth:`RobotPort.estop_hold`)
whatever commands arrive, until a release on ``controller/estop/release``
(the operator's key under access control; a release on the engage key is
ignored and counted). The status says ``estop=engaged`` and why.

Commands are bound to one controller session (``TorqueCommand.session``):
the first to command is served; another session's commands are dropped and
counted (``commands_from_another_controller``) until the served one has
been silent for ``rebind_after_s``, when the newcomer (a restarted
controller) takes over, logged and counted. The robot side holds in the
meantime (stale commands brake).

Each state says which command the robot applied over the last cycle
(``command_seq``, -1 for a hold); a port that finds its robot running on
an old command (:meth:`RobotPort.applying`: the lbr adapter reads the
robot's commanded torque) makes it -1 too, so the controller does not take
the motion for its own. Each also carries the count of such cycles so far
(``held_cycles``), so a controller that skipped states still sees a hold.

Every command passes the :class:`~robot.gate.CommandGate` first; undecodable
payloads, wrong lengths, out-of-sequence answers and late commands are
dropped and counted by reason. Status (counters, loop timing) goes to the
status key at ``status_rate_hz``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import numpy as np

from interfaces.messages import RobotState, ServiceStatus, TorqueCommand
from runtime.loop_hygiene import LoopHygiene
from runtime.loop_stats import LoopStats
from runtime.session import ServiceNode

from .command import Command
from .command_auth import CommandAuth
from .estop import RobotEstop
from .gate import CommandGate
from .guard import Action, RobotGuard
from .guard_log import log_guard_episodes
from .late_answer import LateAnswerDamping
from .port import Applied, Reading, RobotPort
from .served_controller import ServedController
from .server_cycle import CycleRecord, TorqueBuffers
from .server_params import ServerParams
from .server_status import AnswerLatency, StatusOut

__all__ = ["RobotServer", "ServerParams"]

log = logging.getLogger(__name__)


class RobotServer:
    """One robot side on the network. ``run()`` blocks until :attr:`stop` is set or ``max_steps`` cycles.

    Parameters
    ----------
    port : the hardware side. node : an open :class:`ServiceNode`. params : timing.
    service : the name in the status. status_key : where the status goes.

    Attributes
    ----------
    steps : int
        Cycles written so far.
    cycle : CycleRecord
        What the port did with the last cycle (``outcome``, ``braked``, ``applied_seq``) and the holds reported.
    buffers : TorqueBuffers
        The torques reused every cycle (the server's hold, the newest command held, the yield's, the last written).
    estop : RobotEstop
        The e-stop's keys and its reason while engaged. served : ServedController, the controller session served.
    out : StatusOut
        Where and when the status goes. latency : AnswerLatency, a clocked robot's answer latency for the status.
    """

    def __init__(self, port: RobotPort, node: ServiceNode, params: ServerParams, service: str,
                 status_key: str) -> None:
        self.port = port
        self.node = node
        self.p = params
        self.keys = node.keys
        self.out = StatusOut(service, status_key, 1.0 / params.status_rate_hz)
        self.counters: Counter[str] = Counter()
        self.gate = CommandGate(np.asarray(port.capabilities.torque_limits_nm), self.counters,
                                params.tau_rate_nm_s, 1.0 / params.rate_hz, params.contact_tau_rate_nm_s)
        self.stop = threading.Event()
        self.stats = LoopStats()
        self.latency = AnswerLatency()  # clocked ports only
        self.steps = 0
        self.cycle = CycleRecord()
        self._sources: list = []
        self.guard = RobotGuard(params.guard_limits(port), port.limits_model, port.capabilities.gravity_compensated)
        self._reading: Reading | None = None  # the last reading published
        self.late = LateAnswerDamping(port.limits_model, params.late_damping_rad_s, self.gate.tau_max)
        self.buffers = TorqueBuffers(port.n_joints)
        self.auth = CommandAuth(node, self.counters)  # commands' MACs and signed releases, whoever relayed them
        self.estop = RobotEstop(node, self.auth, self.guard, self.counters, log)
        self.served = ServedController(self.auth, self.counters, params.rebind_after_s, log)

    # -- lifecycle ---------------------------------------------------------------------------------
    def run(self) -> int:
        """Serve until stopped; returns the number of written cycles."""
        self.port.activate()
        try:
            loop = self._run_clocked if self.port.clocked else \
                self._run_lockstep if self.p.mode == "lockstep" else self._run_realtime
            loop()
        finally:
            self.port.deactivate()
            self._publish_status(force=True)
        return self.steps

    # -- one cycle ---------------------------------------------------------------------------------
    def _apply(self, command: Command, seq: int = -1) -> None:
        """Write ``command`` (gated torques answering state ``seq``, or a hold) to the port: one cycle, or what the
        e-stop or the guard makes of it (a hold, a brake, a yield). What the port did (:class:`Applied`) decides the
        rest: the next state reports ``seq`` as applied when the port took the command, else -1, and the gate
        counts from what the arm held."""
        self.estop.poll()
        action = self.guard.action
        torques = not command.is_hold
        if self.estop.reason is not None:
            if torques:
                self.counters["commands_held_for_estop"] += 1
            done = self.port.estop_hold()
        elif action != Action.APPLY:  # before the controller's own hold too: a held pad presses on, a repeat speeds on
            done = self._guard_hold(action, torques)
        elif not torques:
            if not self.cycle.braked:
                self.counters["holds_applied"] += 1
            done = self.port.hold()
        else:
            # rate-limited again (a command applied again after a hold climbs from what held the arm), and predicted;
            # not a lock-step run's first command, before which nothing held the arm: taken as the gate passed it
            first = not self.gate.rated
            tau = command.tau_nm
            if self.late.on:  # opt-in: the motion since the state it answers, damped
                tau = self.late.apply(tau, seq)
                self.counters["cycles_late_answer_damped"] += self.late.damped_nm > 0
            tau = tau if first else self.gate.limit_rate(tau)
            if not first and self._speeds_over(tau):
                done = self._guard_hold(self.guard.action, torques)
            else:
                done = self.port.write(tau)
                if done.took_command:
                    self.buffers.written[:] = tau
        self.cycle.took(done, seq)
        if self.cycle.braked:
            held = self.port.held_torque_nm()
            self.gate.ran(self.buffers.written if held is None else held)
        self.steps += 1

    def _guard_hold(self, action: Action, torques: bool) -> Applied:
        """One cycle of what the guard asks instead of the command: a yield, the FAULT's e-stop hold, or a brake."""
        if torques and self.guard.latch.latched:
            self.counters["commands_held_for_guard_fault"] += 1
        if action == Action.YIELD:
            assert self._reading is not None, "a guard's yield before the first reading"
            return self.port.yield_hold(self.guard.damping_into(self._reading.dq_rad_s, self.buffers.damping))
        if action == Action.FAULT:
            return self.port.estop_hold()
        return self.port.speed_hold()

    def _speeds_over(self, tau_nm: np.ndarray) -> bool:
        """Whether one cycle of ``tau_nm`` (n,) [Nm] would take a joint or the tool over its speed brake (the guard's
        prediction; counted and logged as an episode): then the cycle brakes instead."""
        r, rate_hz = self._reading, self.port.capabilities.state_rate_hz or self.p.rate_hz  # a clocked robot's own
        assert r is not None, "a command judged before the first reading"
        entered = self.guard.check_command(r.q_rad, r.dq_rad_s, tau_nm, 1.0 / rate_hz, r.robot_time_ns * 1e-9)
        if entered:
            self._log_guard(entered, r)
        return bool(entered)

    def _in_sequence(self, cmd: TorqueCommand, seq: int) -> bool:
        if cmd.seq != seq:
            self.counters["commands_out_of_sequence"] += 1
            return False
        return True

    # -- loops -------------------------------------------------------------------------------------
    def start_lockstep(self):
        """The lock-step command reader (an :class:`~runtime.session.Inbox`), the first state published."""
        inbox = self.node.inbox(self.keys.robot_command, TorqueCommand)
        self._sources = [inbox]
        self.publish_state()
        return inbox

    def housekeeping(self) -> None:
        """What every pass of a loop does besides the cycle: the e-stop keys read, the status when due."""
        self._publish_status()

    def _run_lockstep(self) -> None:
        inbox = self.start_lockstep()
        last_pub = time.monotonic()
        republish = self.p.republish_s
        t_prev = time.perf_counter_ns()
        while not self.stop.is_set():
            t0 = time.perf_counter_ns()
            cmd = inbox.get(min(republish, 0.05))
            now = time.monotonic()
            self._publish_status()
            if now - last_pub >= republish:  # on every pass: stale-seq chatter must not starve a late peer
                self.publish_state()
                self.counters["states_republished"] += 1
                last_pub = now
            if cmd is None or not self.lockstep_cycle(cmd, t0, t_prev):
                continue
            last_pub = now
            t_prev = time.perf_counter_ns()
            if self.p.max_steps and self.steps >= self.p.max_steps:
                break

    def lockstep_cycle(self, cmd: TorqueCommand, t0_ns: int = 0, t_prev_ns: int = 0) -> bool:
        """One lock-step cycle on ``cmd``: if it answers the current state (served controller, in sequence, passed
        by the gate) the port is written, its extras run and the next state goes out; False when it was dropped
        (counted). ``t0_ns``, ``t_prev_ns``: when the wait for it began and the last cycle ended (perf counter)."""
        if not self.served.accepts(cmd) or not self._in_sequence(cmd, self.steps):
            return False
        command = self.gate.accept(cmd)
        if command is None:
            return False
        t1 = time.perf_counter_ns()
        self._apply(command, cmd.seq)
        self.port.after_cycle(lockstep=True)
        t2 = time.perf_counter_ns()
        self.publish_state()
        t3 = time.perf_counter_ns()
        self.stats.add((t3 - (t_prev_ns or t1)) / 1e3, (t1 - (t0_ns or t1)) / 1e3, (t2 - t1) / 1e3, (t3 - t2) / 1e3)
        return True

    def _run_realtime(self) -> None:
        hygiene = LoopHygiene(counts=self.counters)
        hygiene.start(realtime=True)  # first: its full collection must not count as a stalled first period
        latest = self.node.latest(self.keys.robot_command, TorqueCommand)
        self._sources = [latest]
        period_ns = int(round(1e9 / self.p.rate_hz))
        stale_ns = int(self.p.stale_limit_s * 1e9)
        max_lag = max(1, int(self.p.stale_limit_s * self.p.rate_hz))  # [states] an answer may lag the newest one
        held: Command | None = None  # the newest command accepted (a copy in buffers.held), None before the first
        held_seq = -1
        last_cmd_ns = -stale_ns - 1
        next_ns = time.monotonic_ns()
        t_prev = next_ns
        first_seq = 0  # after a freeze of this loop or a brake, only answers to states published since count
        dropped = "commands_from_before_a_freeze"  # the counter of answers to states before first_seq
        self.publish_state()
        try:
            while not self.stop.is_set():
                t0 = time.monotonic_ns()
                if t0 - t_prev > stale_ns:  # this loop itself stalled (SIGSTOP, a swap storm): whatever is held or
                    held = None  # queued answered a state from before; brake until the controller answers a new one
                    first_seq, dropped = self.steps + 1, "commands_from_before_a_freeze"
                    self.counters["loop_freezes"] += 1
                    log.warning("robot loop frozen for %.0f ms: braking until a fresh answer", (t0 - t_prev) / 1e6)
                cmd = latest.take()
                if cmd is not None and cmd.seq < first_seq:
                    self.counters[dropped] += 1
                elif cmd is not None and self.steps - cmd.seq > max_lag:
                    self.counters["commands_answering_an_old_state"] += 1
                elif cmd is not None and self.served.accepts(cmd):
                    accepted = self.gate.check(cmd)  # the rate limit applies cycle by cycle (_apply)
                    if accepted is not None:
                        held = self.buffers.held.assign(accepted)
                        held_seq, last_cmd_ns = cmd.seq, t0
                fresh = held is not None and t0 - last_cmd_ns <= stale_ns
                if not fresh and held is not None and not self.cycle.braked:
                    # the answers on their way were computed for the arm still moving: only a state from the brake on
                    first_seq, dropped = self.steps + 1, "commands_from_before_a_brake"
                    self.counters["stale_command_brakes"] += 1
                    log.warning("no fresh command for %.0f ms: braking", (t0 - last_cmd_ns) / 1e6)
                t1 = time.monotonic_ns()
                self._apply(held if held is not None and fresh else self.buffers.hold, held_seq)
                self.port.after_cycle(lockstep=False)
                t2 = time.monotonic_ns()
                self.publish_state()
                self._publish_status()
                t3 = time.monotonic_ns()
                self.stats.add((t0 - t_prev) / 1e3, (t1 - t0) / 1e3, (t2 - t1) / 1e3, (t3 - t2) / 1e3)
                t_prev = t0
                if self.p.max_steps and self.steps >= self.p.max_steps:
                    break
                next_ns = hygiene.next_period(self.stats, next_ns, period_ns)
        finally:
            hygiene.stop()

    def _run_clocked(self) -> None:
        """A robot with its own clock: publish each reading as it comes, forward each answer as it arrives.

        An answer to one of the last ``stale_limit_s`` worth of states is forwarded if it is newer than the
        last one forwarded (a controller on its own clock often answers state k after k + 1 has come); a
        state that got no answer before the next one is a late cycle, which the port holds (it repeats the
        last command while that is fresh). In lock-step only the answer to the current state counts.
        """
        hygiene = LoopHygiene(counts=self.counters)
        hygiene.start(realtime=self.p.mode != "lockstep")  # first: its full collection must not age the first state
        wake = threading.Event()  # a new reading or a new command: the loop waits on both at once
        self.port.set_wake(wake)
        inbox = self.node.inbox(self.keys.robot_command, TorqueCommand, maxlen=8, wake=wake)
        self._sources = [inbox]
        lockstep = self.p.mode == "lockstep"
        max_lag = 0 if lockstep else max(1, int(self.p.stale_limit_s * self.p.rate_hz))
        stale_ns = int(self.p.stale_limit_s * 1e9)
        republish_ns = int(self.p.republish_s * 1e9)
        seq = last_applied = -1
        last_good_ns = time.monotonic_ns()
        last_state_ns = last_pub_ns = last_good_ns
        period_ns = int(1e9 / self.port.capabilities.state_rate_hz) if self.port.capabilities.state_rate_hz \
            else 1_000_000
        try:
            while not self.stop.is_set():
                wake.wait(0.001)
                wake.clear()
                t0 = time.monotonic_ns()
                if self.port.wait_reading(0.0):
                    if seq >= 0 and last_applied < seq:
                        self.counters["commands_late"] += 1
                        if not lockstep:
                            self._apply(self.buffers.hold)  # this cycle is held: its answer did not come in time
                    seq += 1
                    self.publish_state(seq)
                    self.stats.add((t0 - last_state_ns) / 1e3, 0.0, 0.0, (time.monotonic_ns() - t0) / 1e3)
                    last_state_ns = last_pub_ns = t0
                elif lockstep and seq >= 0 and last_applied < seq and t0 - last_pub_ns >= republish_ns:
                    self.publish_state(seq)  # a robot that waits for its answer (the lock-step peer): say it again
                    self.counters["states_republished"] += 1
                    last_pub_ns = t0
                cmd = inbox.get(0.0)
                while cmd is not None:
                    if not self.served.accepts(cmd):
                        pass
                    elif cmd.seq <= last_applied or not 0 <= seq - cmd.seq <= max_lag:
                        self.counters["commands_out_of_sequence"] += 1
                    else:
                        since_s = None if lockstep else (time.monotonic_ns() - last_good_ns) * 1e-9
                        command = self.gate.accept(cmd, since_s)
                        if command is not None:
                            self._apply(command, cmd.seq)
                            self.port.after_cycle(lockstep=lockstep)
                            last_applied = cmd.seq
                            last_good_ns = time.monotonic_ns()
                            if cmd.seq == seq:
                                self.latency.add((last_good_ns - last_state_ns) / 1e3)
                                hygiene.collect_due(period_ns - (last_good_ns - last_state_ns))  # the slack now
                            else:
                                self.counters["answers_one_or_more_states_late"] += 1
                    cmd = inbox.get(0.0)
                stale = time.monotonic_ns() - last_state_ns > stale_ns  # this state's age: a slow robot is not late
                if not lockstep and last_applied < seq and not self.cycle.braked and stale:
                    self.counters["stale_command_brakes"] += 1
                    self._apply(self.buffers.hold)
                self._publish_status()
                hygiene.collect_due(0)  # only a pile forces it here (no answer, no slack measured)
                if self.p.max_steps and self.steps >= self.p.max_steps:
                    break
        finally:
            hygiene.stop()

    # -- outputs -----------------------------------------------------------------------------------
    def publish_state(self, seq: int | None = None) -> None:
        """Publish the port's reading as state ``seq`` (default: the cycles written so far)."""
        r = self._reading = self.port.read()
        entered = self.guard.observe(r.q_rad, r.dq_rad_s, r.wrench_world, r.robot_time_ns * 1e-9,
                                     held=self.cycle.braked)
        if entered:
            self._log_guard(entered, r)
        self.gate.touching = self.guard.touching
        seq = self.steps if seq is None else seq
        self.late.record(seq, r.q_rad, r.dq_rad_s)
        applied = self.cycle.command_seq(self.port.applying(), seq)
        self.node.publish(self.keys.robot_state, RobotState(
            seq=seq, stamp_ns=time.monotonic_ns(), q_rad=r.q_rad.tolist(),
            dq_rad_s=r.dq_rad_s.tolist(), tau_nm=r.tau_nm.tolist(), wrench_world=r.wrench_world.tolist(),
            capabilities=self.port.capabilities, robot_time_ns=r.robot_time_ns, wall_ns=time.time_ns(),
            command_seq=applied, estop=self.estop.reason is not None or self.guard.latch.latched,
            held_cycles=self.cycle.held_cycles))

    def _log_guard(self, entered: tuple[str, ...], r: Reading) -> None:
        """Count and log each limit episode that began (and the FAULT-hold, if they latched it)."""
        log_guard_episodes(self.guard, self.p, self.counters, entered, r)

    @property
    def commands_received(self) -> int:
        """Commands taken off the wire so far, good or not (the status's ``commands_received``)."""
        return sum(source.received for source in self._sources)

    def status(self) -> ServiceStatus:
        counters = dict(self.counters)
        for source in self._sources:
            counters["commands_received"] = counters.get("commands_received", 0) + source.received
            for reason, n in list(source.bad.items()):  # Zenoh's thread may add a reason meanwhile
                counters[f"commands_dropped_bad_payload: {reason}"] = n
        counters.update(self.port.counters())
        self.latency.into(counters)  # the round trip through the controller, as the robot side sees it
        counters["estop_engaged"] = int(self.estop.reason is not None)
        counters["guard_fault_latched"] = int(self.guard.latch.latched)
        counters["guard_episodes_in_hold"] = self.guard.episodes_in_hold
        self.estop.dropped_into(counters)
        estop = "" if self.estop.reason is None else f" estop=engaged ({self.estop.reason})"
        served = "" if self.served.session is None else f" controller={self.served.session[:12] or '?'}"
        fault = "" if self.guard.fault_reason is None else f" guard=FAULT ({self.guard.fault_reason})"
        mode = "clocked" if self.port.clocked else self.p.mode
        detail = f"mode={mode} step={self.steps} braked={self.cycle.braked}{served}{estop}{fault}"
        extra = self.port.detail()
        return ServiceStatus(service=self.out.service, seq=self.steps, stamp_ns=time.monotonic_ns(), counters=counters,
                             detail=f"{detail} {extra}".strip(), timing=self.stats.summary())

    def _publish_status(self, force: bool = False) -> None:
        self.auth.housekeeping()  # introductions: a poll and a clock read unless one is due
        self.estop.poll()  # also while no command comes (a lock-step robot waiting for its answer)
        if self.out.due(time.monotonic(), force):
            self.node.publish(self.out.key, self.status())
