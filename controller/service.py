"""The controller as a Zenoh service: lock-step and real-time loops around :class:`~controller.core.ControllerCore`.

Reads ``robot/state``, the stains (``perception/stains``, or ``sim/truth``
with ``stains_from = "truth"``), ``controller/estop`` (engage) and
``controller/estop/release``; writes
``robot/command`` and ``controller/status``.

* lock-step: every new robot state is answered with one command (a state
  re-sent by a waiting sim gets the same command again); time comes from
  the robot's clock (``robot_time_ns``), so a run is deterministic.
* real-time: ticks on absolute deadlines of its own monotonic clock; each
  tick reads the newest state (never waits for it). A state older than
  ``state_timeout_s`` is not answered (counted). Overruns are counted and
  the missed periods skipped, never caught up in a burst.

In both, no state for ``robot_lost_s`` is a FAULT with its reason, and the
controller restarts from the measured pose when states come back (a new
sim starts its ``seq`` again from 0). Zenoh callbacks only hand samples to
one-slot channels or short queues; the loop never blocks on the network.
Cyclic garbage collection is frozen while the loop runs. Malformed samples
on any key are counted (by key and reason, in the status) and dropped.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from collections import Counter

import numpy as np

from interfaces.arm_estimate import ArmEstimate
from interfaces.messages import HOLD, ControllerStatus, RobotState, SimTruth, Stains, TorqueCommand
from runtime.loop_hygiene import LoopHygiene
from runtime.loop_stats import LoopStats
from runtime.session import Latest, ServiceNode

from lampskit.errors import PlanningError

from .command_auth import ControllerAuth
from .control.limits import load_scale
from .control.watch import OverloadWatch
from .core import ControllerCore
from .estop import ControllerEstop
from .params import ControllerParams
from .planner_thread import PlannerThread
from .robot_link import RobotLink
from .sent_answers import SENT_RING, SentAnswers
from .stains_in import stains_update
from .status_out import StatusOut
from .tick_io import LastCommand, TickInput, TickOutput, TickStatus

log = logging.getLogger(__name__)

SERVICE = "controller"
#: On a stop request with the pad on the board, the loop goes on this long at most [s] while it lifts off.
LIFT_ON_STOP_S = 6.0


class ControllerService:
    """One controller on the network. ``run()`` blocks until :attr:`stop` is set or ``max_ticks``."""

    def __init__(self, params: ControllerParams, node: ServiceNode, core: ControllerCore) -> None:
        self.p = params
        self.node = node
        self.keys = node.keys
        self.core = core
        self.counters: Counter[str] = Counter()
        self.stop = threading.Event()
        self.stats = LoopStats()
        self.ticks = 0
        self._out = StatusOut(1.0 / params.status_rate_hz)
        self._link = RobotLink(1.0 / params.rate_hz)
        self._sent = SentAnswers(core.model.nq)  # for the disturbance watch and states said again
        self._session_id = str(node.session.zid())
        self._auth = ControllerAuth(node, self._session_id, self.counters)  # commands' MACs, signed releases
        self._stop_since: float | None = None  # the robot side serves one controller session
        lim = params.limits
        self._overload = OverloadWatch(lim.overload_share, lim.overload_filter_s, lim.overload_persist_s,
                                       lim.overload_slow_share, lim.overload_recover_s)
        self._stains_clock: float | None = None
        self._tick_io = (TickInput.zeros(core.model.nq), TickOutput.zeros(core.model.nq))  # refilled every tick
        self._stains: Latest[SimTruth] | Latest[Stains] = node.latest(self.keys.sim_truth, SimTruth) \
            if params.stains_from == "truth" else node.latest(self.keys.perception_stains, Stains)
        self._estop = ControllerEstop(node, core, self._auth, self.counters, log)

    # ------------------------------------------------------------------ loops
    def run(self) -> int:
        """Serve until stopped; returns the number of ticks answered."""
        gc.collect()
        gc.freeze()
        gc.disable()
        try:
            if self.p.mode == "lockstep":
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            gc.enable()
            gc.unfreeze()
            self._publish_status(force=True)
        return self.ticks

    def lockstep_states(self):
        """The lock-step state reader (an :class:`~runtime.session.Inbox`), its counters in the status."""
        self._state_reader = self.node.inbox(self.keys.robot_state, RobotState, maxlen=8)
        return self._state_reader

    def _run_lockstep(self) -> None:
        states = self.lockstep_states()
        last_state_wall = time.monotonic()
        t_prev = time.perf_counter_ns()
        while not self.exit_now():
            t0 = time.perf_counter_ns()
            state = self._usable(states.get(0.02))
            now = time.monotonic()
            if state is None:
                self._estop.poll()
                self._check_lost(now - last_state_wall)
                self._publish_status()
                continue
            last_state_wall = now
            if self.answer(state, t0, t_prev):
                t_prev = time.perf_counter_ns()
            if self.p.max_ticks and self.ticks >= self.p.max_ticks:
                break

    def answer(self, state: RobotState, t0_ns: int = 0, t_prev_ns: int = 0) -> bool:
        """Answer one lock-step ``state`` (a usable one): the e-stop keys read, a re-sent state answered again,
        a new one ticked and answered, the status when due; True when it was ticked. ``t0_ns``, ``t_prev_ns``:
        when the wait for it began and the last tick ended (perf counter), for the loop's timing."""
        self._estop.poll()
        sent, link = self._sent, self._link
        if state.seq == link.last_seq and sent.last is not None and not link.lost:
            sent.last = self._auth.with_mac(sent.last)  # a key proven since it was sent
            self.node.publish(self.keys.robot_command, sent.last)  # a re-sent state: same answer
            self.counters["states_answered_again"] += 1
            return False
        if state.seq < link.last_seq or link.lost:
            self._robot_back(state)
        elif link.last_seq >= 0 and state.seq != link.last_seq + 1:
            self.counters["states_skipped"] += state.seq - link.last_seq - 1
        dt = link.dt_s(state)
        self._poll_stains(state.robot_time_ns * 1e-9)
        t1 = time.perf_counter_ns()
        tau = self._control(state, dt)
        t2 = time.perf_counter_ns()
        self._send(state.seq, tau)
        self._publish_status()
        t3 = time.perf_counter_ns()
        self.stats.add((t3 - (t_prev_ns or t1)) / 1e3, (t1 - (t0_ns or t1)) / 1e3, (t2 - t1) / 1e3, (t3 - t2) / 1e3)
        return True

    def _run_realtime(self) -> None:
        """Real time, driven by the robot's clock: each state is answered as soon as it arrives (as an FRI client
        answers each packet), so the answer's delay is the tick's cost, never a wait for a deadline of our own.
        Without a state for a nominal period (``rate_hz``) the loop still does its bookkeeping: e-stop, status,
        the robot-lost watch. A state that arrives while an older one is still unanswered replaces it; the states
        never answered are counted as overruns (missed robot periods)."""
        planner = self._start_planner_thread()
        hygiene = LoopHygiene(counts=self.counters)
        hygiene.start(realtime=True)  # first: its full collection must not count as a stalled first period
        states = self.node.inbox(self.keys.robot_state, RobotState, maxlen=1)  # the newest state only
        self._state_reader = states
        nominal_s = 1.0 / self.p.rate_hz
        timeout_ns = int(self.p.state_timeout_or_default_s * 1e9)
        state: RobotState | None = None
        state_ns = 0
        answered_seq = -1
        replaced_seen = 0
        robot_period_ns = int(nominal_s * 1e9)
        t_prev = time.monotonic_ns()
        try:
            while not self.exit_now():
                new = self._usable(states.get(nominal_s))
                t0 = time.monotonic_ns()
                if new is not None:
                    if state is not None and new.seq < state.seq or self._link.lost:
                        self._robot_back(new)
                        answered_seq = -1
                    rate = new.capabilities.state_rate_hz
                    if rate > 0 and int(1e9 / rate) != robot_period_ns:
                        robot_period_ns = int(1e9 / rate)
                        self.counters["robot_rate_changes"] += 1
                        log.info("the robot publishes states at %.0f Hz: this loop follows it", rate)
                    state, state_ns = new, t0
                self._estop.poll()
                t1 = t2 = time.monotonic_ns()
                if state is None or t0 - state_ns > timeout_ns:
                    if state is not None:
                        self.counters["ticks_without_fresh_state"] += 1
                        self._check_lost((t0 - state_ns) / 1e9)
                elif new is not None and state.seq != answered_seq:
                    missed = state.seq - answered_seq - 1 if answered_seq >= 0 else 0
                    if missed > 0:
                        self.stats.overruns += missed  # robot periods left unanswered
                    dt = self._link.dt_s(state)  # the robot's own time, also across skipped periods
                    # the overload is ours: states that came while an older one waited (a state lost on the way
                    # never came: not this loop's fault)
                    ours, replaced_seen = states.replaced - replaced_seen, states.replaced
                    if self._overload.update(ours, dt):
                        self._overloaded()
                    elif self._overload.calm_again(dt):
                        self._calm()
                    lim = self.p.limits
                    self.core.override.load_cap = load_scale(self._overload.share, lim.overload_slow_share,
                                                             lim.overload_share, lim.overload_min_scale)
                    self._poll_stains(t0 / 1e9)
                    t1 = time.monotonic_ns()
                    tau = self._control(state, dt)
                    t2 = time.monotonic_ns()
                    self._send(state.seq, tau)
                    answered_seq = state.seq
                    t3 = time.monotonic_ns()
                    self.stats.add((t0 - t_prev) / 1e3, (t1 - t0) / 1e3, (t2 - t1) / 1e3, (t3 - t2) / 1e3)
                    t_prev = t0
                self._publish_status()
                if self.p.max_ticks and self.ticks >= self.p.max_ticks:
                    break
                hygiene.collect_due(state_ns + robot_period_ns - time.monotonic_ns())  # the slack before the next
        finally:
            hygiene.stop()
            self.core.executor.chain.background = None
            planner.shutdown(wait=False, cancel_futures=True)

    # ------------------------------------------------------------------ pieces
    def exit_now(self) -> bool:
        """After :attr:`stop` is set: True at once with the pad in the air; with it on the board (a cell stopped
        mid-wipe), e-stop (the fast lift) first and True once lifted, or after ``LIFT_ON_STOP_S``."""
        if not self.stop.is_set():
            return False
        ex = self.core.executor
        if self._stop_since is None:
            self._stop_since = time.monotonic()
            if ex.pad_down and self._link.ever_state and not self._link.lost:
                self.counters["lifts_on_stop"] += 1
                log.warning("stop requested with the pad on the board: lifting off first (at most %.0f s)",
                            LIFT_ON_STOP_S)
                ex.estop("cell stopping with the pad on the board: lifting off before exit")
                self._publish_status(force=True)
                return False
            return True
        if not ex.pad_down or self._link.lost:
            return True
        if time.monotonic() - self._stop_since > LIFT_ON_STOP_S:
            log.error("the pad did not lift off within %.0f s of the stop request: exiting anyway", LIFT_ON_STOP_S)
            return True
        return False

    def _start_planner_thread(self) -> PlannerThread:
        """The chain's re-plans and the executor's look points off the 1 kHz path (:mod:`controller.planner_thread`),
        its thread started here, before the loop's thread turns real-time."""
        pool = PlannerThread()
        self.core.executor.chain.background = pool
        self.core.executor.motion.aim.executor = pool
        self.core.posture.job.executor = pool
        return pool

    def _control(self, state: RobotState, dt: float) -> np.ndarray | None:
        """Torques answering ``state``, or None when the tick failed (then the answer is ``hold``)."""
        link = self._link
        link.ever_state = True
        if state.estop != self._estop.robot_engaged:
            self._estop.follow_robot(state.estop)
        applied = self._applied(state)
        link.last_seq = state.seq
        self.ticks += 1
        caps = state.capabilities
        if caps.state_rate_hz != self.core.robot_rate_hz:
            self.core.follow_robot_rate(caps.state_rate_hz)
            log.info("robot states at %.0f Hz: task modes capped at %.0f rad/s", caps.state_rate_hz,
                     self.core.mode_cap_rad_s)
        inp, out = self._tick_io
        inp.set_state(state.q_rad, state.dq_rad_s, state.wrench_world, dt, caps.gravity_compensated)
        inp.tau_max_nm[:] = caps.torque_limits_nm
        last = LastCommand.HELD if link.holds.held_since_last(state.command_seq, state.held_cycles) else \
            LastCommand.UNKNOWN if applied is None else LastCommand.APPLIED
        inp.set_last(last, applied, self._sent.running(state.command_seq) if applied is None else None)
        try:
            status = self.core.tick(inp, out)
        except Exception as exc:  # a bug or an absurd state must not end the loop: fault, count, go on
            self.counters["tick_errors"] += 1
            log.exception("control tick failed")
            self.core.executor.fault(f"control tick failed: {type(exc).__name__}: {exc}")
            self.core.shaper.reset(None)
            return None
        if status == TickStatus.NON_FINITE:  # the core faulted its executor
            self.counters["non_finite_torques"] += 1
            return None
        return out.tau_nm

    def _applied(self, state: RobotState) -> np.ndarray | None:
        """The torques of ours the robot applied between the last answered state and ``state``; None when that is
        not one known command (a hold, a state in between not seen, an answer no longer kept)."""
        if self._link.last_seq < 0 or state.seq != self._link.last_seq + 1:
            return None
        return self._sent.running(state.command_seq)

    def _usable(self, state: RobotState | None) -> RobotState | None:
        """``state`` if this robot model can use it (checked before its seq counts for anything), else None."""
        nq = self.core.model.nq
        if state is not None and len(state.q_rad) != nq:
            self.counters[f"robot_state_dropped: {len(state.q_rad)} joints, the model has {nq}"] += 1
            return None
        return state

    def _send(self, seq: int, tau: np.ndarray | None) -> None:
        """Answer state ``seq``: the torques, or (``tau`` None: the tick failed) ``hold``, which the robot side
        applies by braking; the controller never goes silent on a state it has taken."""
        row, sent = seq % SENT_RING, self._sent
        if tau is None:
            self.counters["holds_sent"] += 1
            zeros = [0.0] * self.core.model.nq
            cmd = TorqueCommand(seq=seq, stamp_ns=time.monotonic_ns(), tau_nm=zeros, mode=HOLD,
                                session=self._session_id, mac=self._auth.mac(seq, HOLD, zeros))
            sent.seq[row] = -1
        else:
            tau_nm = tau.tolist()
            cmd = TorqueCommand(seq=seq, stamp_ns=time.monotonic_ns(), tau_nm=tau_nm, session=self._session_id,
                                mac=self._auth.mac(seq, "torque", tau_nm))
            sent.tau[row] = tau
            sent.seq[row] = seq
        sent.last = cmd
        self.node.publish(self.keys.robot_command, cmd)

    def _check_lost(self, silence_s: float) -> None:
        if self._link.ever_state and not self._link.lost and silence_s >= self.p.robot_lost_or_default_s:
            self._link.lost = True
            self.counters["robot_lost"] += 1
            self.core.executor.robot_lost(f"no robot state for {silence_s * 1000:.0f} ms")
            self._publish_status(force=True)

    def _overloaded(self) -> None:
        """Too many robot states came while an older one waited, for too long: FAULT, which lifts the pad off
        (the loop runs on, slower); the watch starts over, and once the load has passed :meth:`_calm` restarts."""
        self.counters["overload_trips"] += 1
        log.error("%s", self._overload.reason())
        self.core.executor.fault(self._overload.reason())
        self._overload.reset()
        self._overload.faulted()

    def _calm(self) -> None:
        log.warning("the load passed after an overload fault: starting again from the measured pose")
        self.counters["overload_recoveries"] += 1
        self.core.restart()

    def _robot_back(self, state: RobotState) -> None:
        log.warning("robot states back (seq %d after %d): restarting from the measured pose", state.seq,
                    self._link.last_seq)
        self.counters["robot_restarts"] += 1
        self._overload.reset()
        self._link.back()  # a new robot counts its states and held cycles from 0 again
        self._sent.forget()
        self._stains_clock = None  # a new sim's clock starts again
        self.core.restart()

    def _poll_stains(self, clock_s: float) -> None:
        msg = self._stains.take()
        ex = self.core.executor
        if msg is not None:
            update = stains_update(msg, self.p.executor.kappa_remaining, self.counters)
            if update is not None:
                try:
                    ex.set_stains(*update)
                except (ValueError, PlanningError) as exc:  # never the loop's end
                    self.counters[f"stains_rejected: {str(exc)[:60]}"] += 1
                    return
                self._stains_clock = clock_s
                return
        if (self._stains_clock is not None and ex.stains_fresh
                and clock_s - self._stains_clock > self.p.stains_timeout_s):
            self.counters["stains_stale"] += 1
            ex.stains_stale(f"no stains update for {clock_s - self._stains_clock:.1f} s")

    # ------------------------------------------------------------------ status
    def status(self) -> ControllerStatus:
        ex, core = self.core.executor, self.core
        counters = dict(self.counters)
        counters.update(ex.counters)
        counters.update(torque_rate_clipped=core.shaper.clipped_rate, torque_abs_clipped=core.shaper.clipped_abs,
                        robot_estop_engaged=int(self._estop.robot_engaged), estop_latched=int(self._estop.ours),
                        overload_slowed_ticks=core.override.load_limited_ticks,
                        override_jerk_limited_ticks=core.override.jerk_limited_ticks,
                        skill_steps_capped=core.skill_steps_capped,
                        robot_holds_in_skipped_states=self._link.holds.missed,
                        states_after_a_robot_hold=self._link.holds.held)
        posture = getattr(core, "posture", None)  # teach's core has no posture
        if posture is not None:
            counters.update(rest_posture_plans=posture.plans, rest_posture_plans_in_zone=posture.plans_in_zone)
        for name, reader in (("robot_state", getattr(self, "_state_reader", None)), ("stains", self._stains),
                             ("estop", self._estop.engages), ("estop_release", self._estop.releases)):
            if reader is None:
                continue
            counters[f"{name}_received"] = reader.received
            for reason, n in reader.bad.items():
                counters[f"{name}_dropped: {reason}"] = n
        self._out.seq += 1
        return ControllerStatus(seq=self._out.seq, stamp_ns=time.monotonic_ns(), phase=ex.phase, reason=ex.reason,
                                current_mp=ex.current_mp, stain_id=ex.stain_id,
                                normal_force_n=float(core.normal_force_n), timing=self.stats.summary(),
                                counters=counters, wall_ns=time.time_ns(),
                                robot_time_ns=int(core.time_s * 1e9),
                                arm=core.arm.estimate() if hasattr(core, "arm") else ArmEstimate())  # teach: none

    def _publish_status(self, force: bool = False) -> None:
        self._auth.housekeeping()  # introductions: a try_recv and a clock read unless one is due
        if not self._out.due(time.monotonic(), force):
            return
        self.node.publish(self.keys.controller_status, self.status())
        if self.p.publish_trace and self.core.trace is not None:
            self._publish_trace()

    def _publish_trace(self) -> None:
        trace = self.core.trace
        assert trace is not None, "a trace published without its ring"
        msg = self._out.trace_message(trace)
        if msg is not None:
            self.node.publish(self.keys.controller_trace, msg)

