"""The ``robot/*`` protocol of :class:`robot.server.RobotServer` over real Zenoh, with the mock arm (a stepped port).

The server runs in this process on a thread with its own session (listening on a free port, multicast
off); the test plays the controller with a second session connected to it. The mock arm is read
directly where the test needs its truth (steps taken, holds).
"""

from __future__ import annotations

import threading
import time

import msgspec
import numpy as np
import pytest

from interfaces.codec import encode
from interfaces.messages import HOLD, RobotState, ServiceStatus, TorqueCommand
from robot.mock import MockArm
from robot.server import RobotServer, ServerParams
from runtime.config import ZenohSettings
from runtime.session import ServiceNode

from .zenoh_helpers import free_port, wait_for, wait_sample, wait_subscribed


class ServerThread:
    """A :class:`RobotServer` serving ``make_port(node)`` on a thread; :attr:`ctl` is a controller's node.

    ``states`` (every RobotState, in order) and ``status`` (newest ServiceStatus) are readers of
    :attr:`ctl`, subscribed before the server publishes its first state.
    """

    def __init__(self, make_port, params: ServerParams, service: str = "robot") -> None:
        self.port_no = free_port()
        robot_id = f"t{self.port_no}"
        self.settings = ZenohSettings(listen=(f"tcp/127.0.0.1:{self.port_no}",), robot_id=robot_id)
        self.ctl_settings = ZenohSettings(connect=(f"tcp/127.0.0.1:{self.port_no}",), robot_id=robot_id)
        self.make_port, self.params, self.service = make_port, params, service
        self.node = self.ctl = self.thread = self.port = None
        self.error: BaseException | None = None
        self.steps_run: int | None = None

    def __enter__(self) -> ServerThread:
        try:
            self.node = ServiceNode(self.service, self.settings).__enter__()
            self.port = self.make_port(self.node)
            self.server = RobotServer(self.port, self.node, self.params, self.service, self.node.keys.robot_status)
            self.ctl = ServiceNode("controller", self.ctl_settings).__enter__()
            self.keys = self.ctl.keys
            self.states = self.ctl.inbox(self.keys.robot_state, RobotState, maxlen=100_000)
            self.status = self.ctl.latest(self.keys.robot_status, ServiceStatus)
            for key in (self.keys.robot_state, self.keys.robot_status):
                wait_subscribed(self.node.session, key, what=f"the controller subscribing to {key}")
            self.thread = threading.Thread(target=self._run, daemon=True)
            self.thread.start()
            wait_subscribed(self.ctl.session, self.keys.robot_command, what="the server reading robot/command")
        except BaseException:
            self.__exit__()
            raise
        return self

    def _run(self) -> None:
        try:
            self.steps_run = self.server.run()
        except BaseException as exc:  # reported by __exit__, never swallowed
            self.error = exc

    def __exit__(self, *exc) -> None:
        if self.thread is not None:
            self.server.stop.set()
            self.thread.join(10.0)
        if self.port is not None:
            self.port.close()
        for node in (self.ctl, self.node):
            if node is not None:
                node.close()
        assert self.thread is None or not self.thread.is_alive(), "the server did not stop"
        assert self.error is None, f"the server loop died: {self.error!r}"

    # -- the controller's side ---------------------------------------------------------------------
    def command(self, seq: int, tau, mode: str = "torque", session: str = "ctl-a") -> None:
        """Publish a command and wait until the server's reader has it. The control path's publisher drops a sample
        that finds the one before it still queued (``CongestionControl.DROP``, runtime.session.CONTROL_QOS): on a
        loaded machine, of three commands sent back to back the third was lost in 17 of 150 tries; a
        controller answers one state at a time, so one command at a time is what the server meets."""
        before = self.server.commands_received
        self.ctl.publish(self.keys.robot_command, TorqueCommand(seq=seq, stamp_ns=time.monotonic_ns(),
                                                                tau_nm=[float(v) for v in tau], mode=mode,
                                                                session=session))
        wait_for(lambda: self.server.commands_received > before, 5.0, f"the server reading command {seq}")

    def state(self, accept, what: str, timeout_s: float = 5.0) -> RobotState:
        return wait_sample(self.states, accept, timeout_s, what)

    def newest_state(self) -> RobotState:
        """The newest state received (the older ones taken and dropped); waits for one if none is queued."""
        last = self.state(lambda s: True, "a robot state")
        while (s := self.states.get(0.0)) is not None:
            last = s
        return last

    def state_seq(self, seq: int) -> RobotState:
        return self.state(lambda s: s.seq == seq, f"robot state {seq}")

    def wait_status(self, accept, what: str, timeout_s: float = 5.0) -> ServiceStatus:
        return wait_sample(self.status, accept, timeout_s, what)


def lockstep(**kw) -> ServerParams:
    return ServerParams(**{"mode": "lockstep", "republish_s": 0.05, "status_rate_hz": 100.0, **kw})


def mock_step(q: np.ndarray, dq: np.ndarray, tau: np.ndarray, arm: MockArm) -> tuple[np.ndarray, np.ndarray]:
    """One step of the mock's law, written out: I ddq = tau - d dq, semi-implicit Euler."""
    dq = dq + arm.dt_s * (tau - arm.damping * dq) / arm.inertia
    return q + arm.dt_s * dq, dq


def raw_command(seq: int, tau) -> bytes:
    """A TorqueCommand's bytes with any torques (bypassing the constructor's checks)."""
    wire = msgspec.msgpack.decode(encode(TorqueCommand(seq=seq, stamp_ns=1, tau_nm=[0.0] * 7)))
    wire[3] = list(tau)
    return msgspec.msgpack.encode(wire)


def test_lockstep_steps_once_per_answer_in_sequence_and_drops_the_others():
    arm = MockArm(q0_rad=np.linspace(-0.3, 0.3, 7))
    with ServerThread(lambda node: arm, lockstep()) as srv:
        s0 = srv.state_seq(0)
        srv.command(2, [9.0] * 7)  # answers to states that were never sent
        srv.command(1, [9.0] * 7)
        tau = np.arange(1.0, 8.0)
        srv.command(0, tau)
        s1 = srv.state_seq(1)
        srv.command(0, tau)  # the same answer again, now late
        st = srv.wait_status(lambda m: m.counters.get("commands_out_of_sequence", 0) >= 3,
                             "a status counting the three out-of-sequence answers")
        assert st.seq == 1 and arm.steps == 1, "only the answer to state 0 stepped, and once"
        srv.command(1, tau)
        s2 = srv.state_seq(2)
        st = srv.wait_status(lambda m: m.seq == 2, "a status after step 2")
    q1, dq1 = mock_step(np.array(s0.q_rad), np.array(s0.dq_rad_s), tau, arm)
    assert s1.q_rad == q1.tolist() and s1.dq_rad_s == dq1.tolist() and s1.tau_nm == tau.tolist()
    q2, dq2 = mock_step(q1, dq1, tau, arm)
    assert s2.q_rad == q2.tolist() and s2.dq_rad_s == dq2.tolist()
    assert s2.robot_time_ns == 2_000_000 and s2.capabilities.backend == "mock"
    c = st.counters
    assert c["commands_out_of_sequence"] == 3 and c["commands_applied"] == 2 and c["commands_received"] == 5, c
    assert st.detail.startswith("mode=lockstep step=2 braked=False"), st.detail


def test_an_unanswered_state_is_re_sent_until_answered():
    arm = MockArm()
    with ServerThread(lambda node: arm, lockstep(republish_s=0.02)) as srv:
        resent = [srv.state_seq(0) for _ in range(4)]
        assert arm.steps == 0
        srv.command(0, np.zeros(7))
        s1 = srv.state_seq(1)
        st = srv.wait_status(lambda m: m.seq == 1, "a status after the answer")
        assert arm.steps == 1
    assert all(s.q_rad == resent[0].q_rad and s.robot_time_ns == 0 for s in resent)
    assert [s.stamp_ns for s in resent] == sorted({s.stamp_ns for s in resent}), "each re-send is a new publication"
    assert s1.robot_time_ns == 1_000_000
    assert st.counters["states_republished"] >= 3


def test_the_gate_drops_wrong_lengths_clips_limits_and_rate_and_holds_on_request():
    """After a hold the rate limit counts from what the hold applied, never from nothing: no command after it jumps
    more than one cycle's step."""
    arm = MockArm(tau_max_nm=[50.0] * 7)
    with ServerThread(lambda node: arm, lockstep(tau_rate_nm_s=5000.0)) as srv:  # 5 Nm per 1 ms cycle
        s0 = srv.state_seq(0)
        srv.command(0, [0.0] * 6)  # one joint short
        pub = srv.ctl.session.declare_publisher(srv.keys.robot_command)
        pub.put(b"\x00garbage")
        pub.put(raw_command(0, [float("nan")] * 7))
        pub.undeclare()
        srv.command(0, [80.0, 0, 0, 0, 0, 0, -80.0])  # over the 50 Nm limit; the first command has no rate reference
        s1 = srv.state_seq(1)
        srv.command(1, [50.0, 20.0, 0, 0, 0, 0, -50.0])  # joint 2 jumps 20 Nm: 5 Nm allowed
        s2 = srv.state_seq(2)
        srv.command(2, [1e3] * 7, mode=HOLD)  # torques ignored
        s3 = srv.state_seq(3)
        srv.command(3, [50.0, 20.0, 0, 0, 0, 0, 0])  # from what the hold applied (the mock's: 0), not from before it
        s4 = srv.state_seq(4)
        st = srv.wait_status(lambda m: m.seq == 4, "a status after step 4")
        assert arm.steps == 4 and arm.holds == 1
    assert s1.tau_nm == [50.0, 0, 0, 0, 0, 0, -50.0]
    assert s2.tau_nm == [50.0, 5.0, 0, 0, 0, 0, -50.0]
    assert s3.tau_nm == [0.0] * 7 and s3.dq_rad_s == [0.0] * 7 and s3.q_rad == s2.q_rad, "the hold brakes in place"
    assert s4.tau_nm == [5.0, 5.0, 0, 0, 0, 0, 0]
    assert s0.tau_nm == [0.0] * 7
    c = st.counters
    assert c["commands_dropped_wrong_length"] == 1 and c["commands_clipped"] == 1 and c["commands_rate_limited"] == 2
    assert c["commands_hold"] == 1 and c["holds_applied"] == 1 and c["mock_holds"] == 1 and c["commands_applied"] == 3
    bad = {k: v for k, v in c.items() if k.startswith("commands_dropped_bad_payload")}
    assert sum(bad.values()) == 2 and c["commands_received"] == 7, c


@pytest.mark.slow
@pytest.mark.alone
def test_realtime_brakes_without_a_command_and_when_the_command_goes_stale():
    rate_hz, stale_s = 500.0, 0.03
    arm = MockArm(dt_s=1.0 / rate_hz)
    params = ServerParams(mode="realtime", rate_hz=rate_hz, stale_limit_s=stale_s, status_rate_hz=100.0)
    with ServerThread(lambda node: arm, params) as srv:
        first = srv.wait_status(lambda m: m.seq >= 20, "a status after 20 real-time cycles")
        assert first.counters["mock_holds"] == first.seq, "no command yet: every cycle holds"
        srv.command(srv.newest_state().seq, [2.0] * 7)  # once; real time holds the newest command while it is fresh
        st = srv.wait_status(lambda m: m.counters.get("stale_command_brakes", 0) >= 1, "a stale-command brake")
        braked = srv.state(lambda s: s.seq > st.seq + 5, "cycles after the brake")
        later = srv.state(lambda s: s.seq > braked.seq + 20, "20 more cycles")
    torque_steps = arm.steps - arm.holds
    # fresh for stale_limit_s: at most stale_s * rate_hz + 1 cycles (fewer when the loop overran)
    assert 1 <= torque_steps <= stale_s * rate_hz + 1, torque_steps
    assert arm.holds > first.seq
    assert braked.dq_rad_s == [0.0] * 7 and later.q_rad == braked.q_rad and later.tau_nm == [0.0] * 7
    assert braked.q_rad[0] > 0.0, "the command moved the arm while it was fresh"
    assert st.counters["stale_command_brakes"] == 1 and st.counters["commands_applied"] == 1
    assert st.timing.ticks > 20


def test_max_steps_ends_the_run_and_deactivating_leaves_the_arm_holding():
    arm = MockArm()
    with ServerThread(lambda node: arm, lockstep(max_steps=2)) as srv:
        for k in range(2):
            srv.state_seq(k)
            srv.command(k, [1.0] * 7)
        srv.thread.join(5.0)
        assert not srv.thread.is_alive() and srv.steps_run == 2
        final = srv.wait_status(lambda m: m.seq == 2, "the final status")
    assert arm.steps == 3 and arm.holds == 1, "two torque steps, then deactivate's hold"
    assert arm.dq.tolist() == [0.0] * 7 and final.counters["commands_applied"] == 2


@pytest.mark.attack('estop', '40 Nm commands during an e-stop',
                    'the robot side holds, the arm unmoved')
def test_the_robot_side_holds_while_the_estop_is_engaged_whatever_is_commanded():
    """Lock-step: every answer still steps the arm, but as a hold while e-stopped (a rogue or a broken controller
    cannot move it); a release on the engage key changes nothing; the release key does."""
    from interfaces.messages import Estop

    arm = MockArm(q0_rad=np.zeros(7))
    with ServerThread(lambda node: arm, lockstep()) as srv:
        for key in (srv.keys.controller_estop, srv.keys.controller_estop_release):
            wait_subscribed(srv.ctl.session, key, what=f"the server reading {key}")
        srv.state_seq(0)
        srv.ctl.publish(srv.keys.controller_estop, Estop(stamp_ns=1, engaged=True, reason="red button", source="op"))
        srv.ctl.publish(srv.keys.controller_estop, Estop(stamp_ns=2, engaged=False, reason="sneaky", source="x"))
        # samples of two keys may arrive in either order: command only once the e-stop is seen (it is polled
        # before every cycle; a lock-step server re-sends state 0 meanwhile, so its status comes)
        srv.wait_status(lambda m: m.counters.get("estop_engaged") == 1, "the e-stop seen by the robot side")
        for seq in range(5):
            srv.command(seq, [40.0] * 7)
            assert srv.state_seq(seq + 1).estop, "every state says the robot side is e-stopped"
        st = srv.wait_status(lambda m: m.seq == 5, "a status after 5 steps")
        assert np.all(arm.q == 0.0) and arm.holds == 5, "held five cycles, not moved by 40 Nm"
        assert "estop=engaged (red button (op))" in st.detail and st.counters["estop_engaged"] == 1
        assert st.counters["commands_held_for_estop"] == 5
        assert st.counters["estop_releases_ignored_on_the_engage_key"] == 1
        srv.ctl.publish(srv.keys.controller_estop_release, Estop(stamp_ns=3, engaged=False, reason="ok", source="op"))
        srv.wait_status(lambda m: m.counters.get("estop_engaged") == 0, "the release seen")
        srv.command(5, [40.0] * 7)
        assert not srv.state_seq(6).estop
        st = srv.wait_status(lambda m: m.seq == 6, "a status after the release")
        assert np.all(arm.q > 0.0) and st.counters["estop_engaged"] == 0 and "estop" not in st.detail.split()[-1]


@pytest.mark.attack('torques', 'a second controller session commands the robot',
                    'dropped and counted; a restarted one served after 0.5 s of silence')
def test_commands_are_bound_to_the_controller_session_served_and_each_state_says_which_it_applied():
    """A second controller (another session, even answering the right state) is dropped and counted while the one
    served keeps commanding; once that one has been silent for ``rebind_after_s`` the newcomer (a restarted
    controller) is served. Each state names the command applied over the cycle before it (-1: a hold) and counts
    the held cycles so far (a state said again while waiting is one cycle)."""
    arm = MockArm(q0_rad=np.zeros(7))
    with ServerThread(lambda node: arm, lockstep(rebind_after_s=0.3)) as srv:
        first = srv.state_seq(0)
        assert first.command_seq == -1 and first.held_cycles == 1
        srv.command(0, [1.0] * 7, session="ctl-a")
        second = srv.state_seq(1)
        assert second.command_seq == 0 and second.held_cycles == 1
        srv.command(1, [-30.0] * 7, session="ctl-b")  # the right seq, the wrong controller
        srv.command(1, [1.0] * 7, session="ctl-a")
        assert srv.state_seq(2).command_seq == 1
        st = srv.wait_status(lambda m: m.counters.get("commands_from_another_controller", 0) == 1,
                             "the other controller's command counted")
        assert arm.steps == 2 and np.all(arm.q > 0.0), "only ctl-a's torques moved the arm"
        assert "controller=ctl-a" in st.detail
        srv.command(2, [0.0] * 7, mode=HOLD, session="ctl-a")
        assert srv.state_seq(3).command_seq == -1, "a hold applies none of the controller's torques"
        assert srv.state_seq(3).held_cycles == 2
        time.sleep(0.4)  # ctl-a silent longer than rebind_after_s: ctl-b (a restarted controller) takes over
        srv.command(3, [1.0] * 7, session="ctl-b")
        fourth = srv.state_seq(4)
        assert fourth.command_seq == 3 and fourth.held_cycles == 2, "state 3, said again while waiting, is one cycle"
        srv.command(4, [1.0] * 7, session="ctl-a")  # the old session is now the other one
        srv.command(4, [1.0] * 7, session="ctl-b")
        srv.state_seq(5)
        st = srv.wait_status(lambda m: m.seq == 5 and m.counters.get("commands_from_another_controller") == 2,
                             "ctl-a dropped after the change")
    assert st.counters["controller_changes"] == 1 and "controller=ctl-b" in st.detail


class FreezingArm(MockArm):
    """A mock arm whose write stalls the server's loop once for ``freeze_s`` when :attr:`freeze` is set."""

    freeze_s = 0.15

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.freeze = threading.Event()
        self.frozen = threading.Event()

    def after_cycle(self, lockstep: bool) -> None:
        if self.freeze.is_set():
            self.freeze.clear()
            self.frozen.set()
            time.sleep(self.freeze_s)
            self.frozen.clear()


@pytest.mark.slow
@pytest.mark.alone
def test_after_its_own_loop_froze_the_robot_side_brakes_until_the_controller_answers_a_fresh_state():
    """After the robot side's own loop froze, no pre-freeze command may be applied: the held command and an
    answer to a state from before the freeze are both dropped; the arm holds until an answer to a new state."""
    arm = FreezingArm(q0_rad=np.zeros(7))
    params = ServerParams(mode="realtime", rate_hz=500.0, stale_limit_s=0.05, status_rate_hz=100.0)
    with ServerThread(lambda node: arm, params) as srv:
        before = srv.state(lambda s: s.seq >= 10, "ten real-time cycles")
        srv.command(before.seq, [1.0] * 7)
        srv.state(lambda s: s.command_seq == before.seq, "the command applied")
        arm.freeze.set()
        wait_for(arm.frozen.is_set, what="the server's loop frozen")
        srv.command(before.seq + 1, [1.0] * 7)  # answers a state from before the freeze, arrives during it
        wait_for(lambda: not arm.frozen.is_set(), what="the loop running again")
        thawed_ns = time.monotonic_ns()
        after = srv.state(lambda s: s.stamp_ns > thawed_ns, "a state after the freeze")
        assert after.command_seq == -1
        later = [srv.state(lambda s, k=k: s.seq == after.seq + k, f"state {after.seq + k}") for k in (1, 2, 3)]
        assert all(s.command_seq == -1 and s.dq_rad_s == [0.0] * 7 for s in later), "held, not driven"
        fresh = srv.newest_state().seq  # the states queued for the test lag the server's
        srv.command(fresh, [1.0] * 7)
        srv.state(lambda s: s.command_seq == fresh, "a fresh answer applied")
        st = srv.wait_status(lambda m: m.counters.get("commands_from_before_a_freeze", 0) >= 1, "the drop counted")
    assert st.counters["loop_freezes"] == 1, st.counters


@pytest.mark.slow
@pytest.mark.alone
def test_after_a_stale_brake_only_an_answer_to_a_state_from_the_brake_on_is_applied():
    """A controller frozen for longer than the stale limit answers its backlog when it wakes: torques computed for
    the arm still moving (its damping of that motion drives the braked arm back; in a real-time cell with commands
    thinned this pressed the pad to 46 N). After a stale-command brake an answer to a state from before the brake
    is dropped, and so is any answer lagging more than the stale limit; an answer to a state since is applied."""
    rate_hz, stale_s = 500.0, 0.2  # the stale limit as 100 states: the test's own latency is no old state
    arm = MockArm(q0_rad=np.zeros(7), dt_s=1.0 / rate_hz)
    params = ServerParams(mode="realtime", rate_hz=rate_hz, stale_limit_s=stale_s, status_rate_hz=100.0)
    with ServerThread(lambda node: arm, params) as srv:
        before = srv.state(lambda s: s.seq >= 10, "ten real-time cycles")
        srv.command(before.seq, [1.0] * 7)
        srv.state(lambda s: s.command_seq == before.seq, "the command applied")
        braked = srv.state(lambda s: s.seq > before.seq and s.command_seq == -1, "the first state of the brake")
        srv.command(braked.seq - 1, [1.0] * 7)  # answers the last state before the brake
        st = srv.wait_status(lambda m: m.counters.get("commands_from_before_a_brake", 0) >= 1, "the drop counted")
        held = srv.newest_state()
        later = [srv.state(lambda s, k=k: s.seq == held.seq + k, f"state {held.seq + k}") for k in (1, 2, 3)]
        assert all(s.command_seq == -1 and s.dq_rad_s == [0.0] * 7 for s in later), "held, not driven"
        fresh = srv.newest_state().seq
        srv.command(fresh, [1.0] * 7)
        srv.state(lambda s: s.command_seq == fresh, "an answer to a state of the brake applied")
        srv.state(lambda s: s.seq > fresh + 2 * stale_s * rate_hz, "two stale limits' states on")
        srv.command(srv.newest_state().seq - int(1.5 * stale_s * rate_hz), [3.0] * 7)  # lags 1.5 stale limits
        st = srv.wait_status(lambda m: m.counters.get("commands_answering_an_old_state", 0) >= 1, "the old answer")
        after = [srv.newest_state() for _ in range(3)]
    assert all(s.command_seq in (-1, fresh) for s in after), [s.command_seq for s in after]
    assert st.counters["stale_command_brakes"] >= 1 and st.counters["commands_applied"] == 2, st.counters


@pytest.mark.attack('torques', 'commands that drive a joint over 0.95 of its speed limit',
                    'braked')
def test_a_joint_over_its_speed_brake_is_braked_whatever_is_commanded():
    """A starved controller answering late once spun the sim's A6 to 7.7x its limit (CI load). The robot side
    brakes every joint while one is (or by the next cycle will be) faster than 0.95 of its limit and lets go only
    under 0.8 (a brake released where it engaged hands the arm straight back to what sped it up); each episode is
    counted. A controller that keeps at it (five episodes within a second) is held, whatever it sends, until the
    operator's e-stop release: the state says e-stop meanwhile, the status names the FAULT."""
    from interfaces.messages import Estop

    arm = MockArm(damping_nm_s_rad=0.0, dq_max_rad_s=[1.0] * 7, brake_rad_s2=20.0)
    tau = np.array([5.0, 0, 0, 0, 0, 0, 0])  # 10 rad/s^2 on A1: 0.01 rad/s a cycle; the brake takes 0.02 off
    states = []
    with ServerThread(lambda node: arm, lockstep()) as srv:
        wait_subscribed(srv.ctl.session, srv.keys.controller_estop_release, what="the server reading the release")
        for seq in range(300):
            states.append(srv.state_seq(seq))
            srv.command(seq, tau)
        st = srv.wait_status(lambda m: m.seq >= 300, "every command served")
        srv.ctl.publish(srv.keys.controller_estop_release, Estop(stamp_ns=1, engaged=False, reason="ok", source="op"))
        srv.wait_status(lambda m: m.counters.get("guard_fault_latched") == 0, "the release seen")
        srv.state_seq(300)
        srv.command(300, tau)
        after = srv.state_seq(301)
    speed = np.array([abs(s.dq_rad_s[0]) for s in states])
    applied = np.array([s.command_seq >= 0 for s in states])
    assert speed.max() <= 0.95 + 0.01, speed.max()  # the look-ahead: at most one cycle's gain past the brake
    # a brake begins at 0.95 (or one gain short of it) and lets go only under 0.8
    starts = [k for k in range(1, 300) if applied[k - 1] and not applied[k]]  # the fifth latches
    ends = [k for k in range(1, 300) if not applied[k - 1] and applied[k]]
    assert len(starts) == 5 and all(speed[k - 1] >= 0.93 for k in starts), (starts, speed[[k - 1 for k in starts]])
    assert len(ends) >= 4 and all(speed[k - 1] < 0.8 for k in ends[1:]), (ends, speed[[k - 1 for k in ends]])
    assert all(speed[k - 1] > 0.8 - 0.021 for k in ends[1:]), "let go at the band's edge (one brake step), not at rest"
    c = st.counters
    assert c["joint_speed_brakes"] == 5 and c["guard_faults"] == 1 and c["guard_fault_latched"] == 1, c
    latched = int(np.argmax([s.estop for s in states]))
    assert 0 < latched and all(s.estop for s in states[latched:]), "every state says so once latched"
    assert all(s.command_seq == -1 for s in states[latched + 1:]), "held from the cycle after"
    assert speed[-1] == 0.0 and c["commands_held_for_guard_fault"] == 300 - latched, (c, latched)
    assert "guard=FAULT (5 limit episodes within 1 s" in st.detail, st.detail
    assert not after.estop and after.command_seq == 300, "served again after the operator's release"


def test_without_declared_limits_there_is_no_speed_brake():
    arm = MockArm(damping_nm_s_rad=0.0)
    with ServerThread(lambda node: arm, lockstep()) as srv:
        for seq in range(150):
            s = srv.state_seq(seq)
            srv.command(seq, [5.0, 0, 0, 0, 0, 0, 0])
        s = srv.state_seq(150)
    assert s.dq_rad_s[0] > 1.4 and s.command_seq == 149, "every command applied"
