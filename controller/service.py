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
from interfaces.messages import (HOLD, ControllerStatus, ControllerTrace, Estop, RobotState, SimTruth, Stains,
                                 TorqueCommand)
from runtime.loop_hygiene import LoopHygiene
from runtime.loop_stats import LoopStats
from runtime.session import ServiceNode

from lampskit.errors import PlanningError

from .command_auth import ControllerAuth
from .control.limits import load_scale
from .control.watch import OverloadWatch
from .core import TRACE_COLUMNS, ControllerCore
from .params import ControllerParams
from .planner_thread import PlannerThread
from .robot_holds import RobotHolds
from .stains_in import stains_update

log = logging.getLogger(__name__)

SERVICE = "controller"
#: How many answers are kept to look up the one a robot state says it applied (>= the states a real-time
#: robot may run ahead of its answers).
SENT_RING = 64
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
        self._status_period_s = 1.0 / params.status_rate_hz
        self._next_status = 0.0
        self._status_seq = 0
        self._trace_sent = 0
        self._trace_seq = 0
        self._last_seq = -1
        self._holds = RobotHolds()  # a hold in the states skipped, from the robot's count
        self._last_robot_ns: int | None = None
        self._last_command: TorqueCommand | None = None
        # the torques sent for the last SENT_RING states (row seq % SENT_RING; -1: a hold), for the disturbance watch
        self._sent_tau = np.zeros((SENT_RING, core.model.nq))
        self._sent_seq = np.full(SENT_RING, -1, dtype=np.int64)
        self._session_id = str(node.session.zid())
        self._auth = ControllerAuth(node, self._session_id, self.counters)  # commands' MACs, signed releases
        self._stop_since: float | None = None  # the robot side serves one controller session
        lim = params.limits
        self._overload = OverloadWatch(lim.overload_share, lim.overload_filter_s, lim.overload_persist_s,
                                       lim.overload_slow_share, lim.overload_recover_s)
        self._stains_clock = None
        self._lost = False
        self._ever_state = False
        self._nq = core.model.nq
        if params.stains_from == "truth":
            self._stains = node.latest(self.keys.sim_truth, SimTruth)
        else:
            self._stains = node.latest(self.keys.perception_stains, Stains)
        self._estops = node.inbox(self.keys.controller_estop, Estop, maxlen=32)
        self._releases = node.inbox(self.keys.controller_estop_release, Estop, maxlen=32)
        self._robot_estop = False  # the last state said the robot side's e-stop is engaged
        self._estop_ours = False  # our own e-stop is latched (an engage on controller/estop, not yet released)

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
                self._poll_estop()
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
        self._poll_estop()
        if state.seq == self._last_seq and self._last_command is not None and not self._lost:
            self._last_command = self._auth.with_mac(self._last_command)  # a key proven since it was sent
            self.node.publish(self.keys.robot_command, self._last_command)  # a re-sent state: same answer
            self.counters["states_answered_again"] += 1
            return False
        if state.seq < self._last_seq or self._lost:
            self._robot_back(state)
        elif self._last_seq >= 0 and state.seq != self._last_seq + 1:
            self.counters["states_skipped"] += state.seq - self._last_seq - 1
        dt = self._dt_from_robot_clock(state)
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
                    if state is not None and new.seq < state.seq or self._lost:
                        self._robot_back(new)
                        answered_seq = -1
                    rate = new.capabilities.state_rate_hz
                    if rate > 0 and int(1e9 / rate) != robot_period_ns:
                        robot_period_ns = int(1e9 / rate)
                        self.counters["robot_rate_changes"] += 1
                        log.info("the robot publishes states at %.0f Hz: this loop follows it", rate)
                    state, state_ns = new, t0
                self._poll_estop()
                t1 = t2 = time.monotonic_ns()
                if state is None or t0 - state_ns > timeout_ns:
                    if state is not None:
                        self.counters["ticks_without_fresh_state"] += 1
                        self._check_lost((t0 - state_ns) / 1e9)
                elif new is not None and state.seq != answered_seq:
                    missed = state.seq - answered_seq - 1 if answered_seq >= 0 else 0
                    if missed > 0:
                        self.stats.overruns += missed  # robot periods left unanswered
                    dt = self._dt_from_robot_clock(state)  # the robot's own time, also across skipped periods
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
            if ex.pad_down and self._ever_state and not self._lost:
                self.counters["lifts_on_stop"] += 1
                log.warning("stop requested with the pad on the board: lifting off first (at most %.0f s)",
                            LIFT_ON_STOP_S)
                ex.estop("cell stopping with the pad on the board: lifting off before exit")
                self._publish_status(force=True)
                return False
            return True
        if not ex.pad_down or self._lost:
            return True
        if time.monotonic() - self._stop_since > LIFT_ON_STOP_S:
            log.error("the pad did not lift off within %.0f s of the stop request: exiting anyway", LIFT_ON_STOP_S)
            return True
        return False

    def _start_planner_thread(self) -> PlannerThread:
        """The chain's re-plans off the 1 kHz path (:mod:`controller.planner_thread`), its thread started here,
        before the loop's thread turns real-time."""
        pool = PlannerThread()
        self.core.executor.chain.background = pool
        return pool

    def _control(self, state: RobotState, dt: float) -> np.ndarray | None:
        """Torques answering ``state``, or None when the tick failed (then the answer is ``hold``)."""
        self._ever_state = True
        if state.estop != self._robot_estop:
            self._follow_robot_estop(state.estop)
        applied = self._applied(state)
        self._last_seq = state.seq
        self.ticks += 1
        q = np.asarray(state.q_rad)
        dq = np.asarray(state.dq_rad_s)
        wrench = np.asarray(state.wrench_world)
        caps = state.capabilities
        if caps.state_rate_hz != self.core.robot_rate_hz:
            self.core.follow_robot_rate(caps.state_rate_hz)
            log.info("robot states at %.0f Hz: task modes capped at %.0f rad/s", caps.state_rate_hz,
                     self.core.mode_cap_rad_s)
        try:
            tau = self.core.tick(q, dq, wrench, caps.gravity_compensated, dt, np.asarray(caps.torque_limits_nm),
                                 applied, robot_held=self._holds.held_since_last(state.command_seq,
                                                                                  state.held_cycles),
                                 running_nm=self._running(state) if applied is None else None)
        except Exception as exc:  # a bug or an absurd state must not end the loop: fault, count, go on
            self.counters["tick_errors"] += 1
            log.exception("control tick failed")
            self.core.executor.fault(f"control tick failed: {type(exc).__name__}: {exc}")
            self.core.shaper.reset(None)
            return None
        if not np.isfinite(tau).all():
            self.counters["non_finite_torques"] += 1
            self.core.shaper.reset(None)
            self.core.executor.fault("the control law gave non-finite torques (absurd robot state?)")
            return None
        return tau

    def _applied(self, state: RobotState) -> np.ndarray | None:
        """The torques of ours the robot applied between the last answered state and ``state``; None when that is
        not one known command (a hold, a state in between not seen, an answer no longer kept)."""
        if self._last_seq < 0 or state.seq != self._last_seq + 1:
            return None
        return self._running(state)

    def _running(self, state: RobotState) -> np.ndarray | None:
        """The torques of the command the robot ran on over the cycle before ``state`` (states skipped or not), if
        it is one of ours still kept; None for a hold."""
        c = state.command_seq
        if c < 0:
            return None
        row = c % SENT_RING
        return self._sent_tau[row] if self._sent_seq[row] == c else None

    def _usable(self, state: RobotState | None) -> RobotState | None:
        """``state`` if this robot model can use it (checked before its seq counts for anything), else None."""
        if state is not None and len(state.q_rad) != self._nq:
            self.counters[f"robot_state_dropped: {len(state.q_rad)} joints, the model has {self._nq}"] += 1
            return None
        return state

    def _send(self, seq: int, tau: np.ndarray | None) -> None:
        """Answer state ``seq``: the torques, or (``tau`` None: the tick failed) ``hold``, which the robot side
        applies by braking; the controller never goes silent on a state it has taken."""
        row = seq % SENT_RING
        if tau is None:
            self.counters["holds_sent"] += 1
            zeros = [0.0] * self._nq
            cmd = TorqueCommand(seq=seq, stamp_ns=time.monotonic_ns(), tau_nm=zeros, mode=HOLD,
                                session=self._session_id, mac=self._auth.mac(seq, HOLD, zeros))
            self._sent_seq[row] = -1
        else:
            tau_nm = tau.tolist()
            cmd = TorqueCommand(seq=seq, stamp_ns=time.monotonic_ns(), tau_nm=tau_nm, session=self._session_id,
                                mac=self._auth.mac(seq, "torque", tau_nm))
            self._sent_tau[row] = tau
            self._sent_seq[row] = seq
        self._last_command = cmd
        self.node.publish(self.keys.robot_command, cmd)

    def _dt_from_robot_clock(self, state: RobotState) -> float:
        """Time since the last answered state on the robot's clock; the nominal period when that is unusable."""
        dt = 1.0 / self.p.rate_hz
        if self._last_robot_ns is not None and state.robot_time_ns > self._last_robot_ns:
            measured = (state.robot_time_ns - self._last_robot_ns) * 1e-9
            if measured <= 0.1:
                dt = measured
        self._last_robot_ns = state.robot_time_ns
        return dt

    def _check_lost(self, silence_s: float) -> None:
        if self._ever_state and not self._lost and silence_s >= self.p.robot_lost_or_default_s:
            self._lost = True
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
                    self._last_seq)
        self.counters["robot_restarts"] += 1
        self._overload.reset()
        self._lost = False
        self._last_robot_ns = None
        self._last_seq = -1
        self._last_command = None
        self._sent_seq[:] = -1  # a new robot counts its states from 0 again
        self._holds.reset()  # and its held cycles
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

    def _follow_robot_estop(self, engaged: bool) -> None:
        """The robot side's e-stop and ours agree: while its e-stop is engaged (it holds whatever we send) we are
        in ESTOP too, also when the engage never reached us (a lost sample, a controller started afterwards); when
        the operator's release reaches it, we resume unless our own e-stop is still latched."""
        self._robot_estop = engaged
        if engaged:
            self.counters["robot_estops_seen"] += 1
            log.warning("the robot side reports its e-stop engaged: ESTOP until it is released")
            if not self._estop_ours:
                self.core.executor.estop("e-stop engaged on the robot side")
        elif not self._estop_ours:
            log.warning("the robot side's e-stop released")
            self.core.executor.clear()

    def _poll_estop(self) -> None:
        """Engage on ``controller/estop``; release only from ``controller/estop/release`` (the operator's key under
        access control): a release on the engage key is ignored and counted. A release while the robot side
        still reports its e-stop engaged waits for it (:meth:`_follow_robot_estop`)."""
        for inbox, release_key in ((self._estops, False), (self._releases, True)):
            while True:
                e = inbox.get(0.0)
                if e is None:
                    break
                if e.engaged:
                    log.warning("e-stop from %s: %s", e.source or "?", e.reason)
                    self._estop_ours = True
                    self.core.executor.estop(f"e-stop: {e.reason}" + (f" ({e.source})" if e.source else ""))
                elif release_key and not self._auth.release_ok(e):
                    continue  # not the operator's signature, or a replay: counted and logged
                elif release_key:
                    log.warning("e-stop released by %s", e.source or "?")
                    self.counters["estop_releases"] += 1
                    self._estop_ours = False
                    if self._robot_estop:
                        self.core.executor.estop("released here; waiting for the robot side's e-stop release")
                    else:
                        self.core.executor.clear()
                else:
                    self.counters["estop_releases_ignored_on_the_engage_key"] += 1
                    log.warning("e-stop release from %s on the engage key ignored (releases go to %s)",
                                e.source or "?", self.keys.controller_estop_release)

    # ------------------------------------------------------------------ status
    def status(self) -> ControllerStatus:
        ex, core = self.core.executor, self.core
        counters = dict(self.counters)
        counters.update(ex.counters)
        counters.update(torque_rate_clipped=core.shaper.clipped_rate, torque_abs_clipped=core.shaper.clipped_abs,
                        robot_estop_engaged=int(self._robot_estop), estop_latched=int(self._estop_ours),
                        overload_slowed_ticks=core.override.load_limited_ticks,
                        override_jerk_limited_ticks=core.override.jerk_limited_ticks,
                        skill_steps_capped=core.skill_steps_capped, robot_holds_in_skipped_states=self._holds.missed)
        for name, reader in (("robot_state", getattr(self, "_state_reader", None)), ("stains", self._stains),
                             ("estop", self._estops), ("estop_release", self._releases)):
            if reader is None:
                continue
            counters[f"{name}_received"] = reader.received
            for reason, n in reader.bad.items():
                counters[f"{name}_dropped: {reason}"] = n
        self._status_seq += 1
        return ControllerStatus(seq=self._status_seq, stamp_ns=time.monotonic_ns(), phase=ex.phase, reason=ex.reason,
                                current_mp=ex.current_mp, stain_id=ex.stain_id,
                                normal_force_n=float(core.normal_force_n), timing=self.stats.summary(),
                                counters=counters, wall_ns=time.time_ns(),
                                robot_time_ns=int(core.time_s * 1e9),
                                arm=core.arm.estimate() if hasattr(core, "arm") else ArmEstimate())  # teach: none

    def _publish_status(self, force: bool = False) -> None:
        self._auth.housekeeping()  # introductions: a try_recv and a clock read unless one is due
        now = time.monotonic()
        if not force and now < self._next_status:
            return
        self._next_status = now + self._status_period_s
        self.node.publish(self.keys.controller_status, self.status())
        if self.p.publish_trace and self.core.trace is not None:
            self._publish_trace()

    def _publish_trace(self) -> None:
        first, rows, dropped = self.core.trace.since(self._trace_sent)
        if not len(rows):
            return
        self._trace_sent = first + len(rows)
        self._trace_seq += 1
        self.node.publish(self.keys.controller_trace, ControllerTrace(
            seq=self._trace_seq, stamp_ns=time.monotonic_ns(), columns=list(TRACE_COLUMNS), first_tick=first,
            n_rows=len(rows), data=rows.astype("<f8").tobytes(), dropped=dropped))

