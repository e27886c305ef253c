"""The adapter's watches on the robot's clock, its connection quality and the commands it applied, and the
stand-in's failures behind them, as pure state (no network): :mod:`robot.lbr.watches`,
:class:`robot.lbr.compensation.AppliedWatch`, :func:`robot.lbr.arming.arming_refusal`, and
:class:`sim.lbr_stack.stack.FriLink`, :class:`~sim.lbr_stack.stack.RobotSession`,
:func:`~sim.lbr_stack.stack.reported_commanded_torque`, :func:`sim.lbr_stack.peer.next_manager_deadline`.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from robot.lbr.arming import arming_refusal
from robot.lbr.compensation import AppliedWatch
from robot.lbr.msgs import ConnectionQuality, LbrState, SessionState
from robot.lbr.params import LbrParams
from robot.lbr.watches import AppliedCheck, Clock, ClockWatch, QualityWatch, TorqueResolution
from sim.lbr_stack.params import LbrPeerParams
from sim.lbr_stack.peer import next_manager_deadline
from sim.lbr_stack.stack import FriLink, RobotSession, reported_commanded_torque

MS = 1_000_000
Q = ConnectionQuality


# -- the robot's clock ----------------------------------------------------------------------------------------

def test_a_stamp_that_stops_advancing_is_frozen_after_the_set_periods_of_our_clock_once_answered():
    """1 ms states, a manager re-publishing the last one every 1 ms: REPEATED until 20 periods (20 ms of our clock)
    after its first arrival, then FROZEN once, with the reason; a new stamp ends the episode."""
    w = ClockWatch(periods=20)
    assert w.update(5 * MS, 0.001, 100 * MS, answered_ns=None) == Clock.ADVANCED
    verdicts = [w.update(5 * MS, 0.001, (100 + k) * MS, answered_ns=100 * MS) for k in range(1, 26)]
    assert verdicts[:19] == [Clock.REPEATED] * 19 and verdicts[19] == Clock.FROZEN, verdicts
    assert verdicts[20:] == [Clock.REPEATED] * 5, "judged once an episode"
    assert w.frozen and w.frozen_ns == 25 * MS
    assert w.reason.startswith("the robot's time stamp has not advanced for 20 ms (over 20 periods of 1 ms) while "
                               "its states keep arriving: the FRI link is lost"), w.reason
    assert w.update(6 * MS, 0.001, 130 * MS, answered_ns=100 * MS) == Clock.ADVANCED and not w.frozen


def test_an_unanswered_stamp_said_again_is_a_robot_waiting_not_a_lost_link():
    """The lock-step stand-in re-sends a state until it is answered (every 50 ms): never frozen while unanswered;
    answered late, the periods count from the answer (a re-sent copy in flight arrives just after it)."""
    w = ClockWatch(periods=20)
    w.update(5 * MS, 0.001, 0, answered_ns=None)
    assert all(w.update(5 * MS, 0.001, k * 50 * MS, answered_ns=None) == Clock.REPEATED for k in range(1, 10))
    assert w.update(5 * MS, 0.001, 501 * MS, answered_ns=500 * MS) == Clock.REPEATED
    assert w.update(5 * MS, 0.001, 511 * MS, answered_ns=500 * MS) == Clock.REPEATED
    assert w.update(5 * MS, 0.001, 521 * MS, answered_ns=500 * MS) == Clock.FROZEN


def test_a_copy_after_a_silence_is_a_stalled_publisher_and_starts_the_count_again():
    """A manager thread the host stalled for longer than the allowance publishes the state it last read once more,
    then a new one: not a lost link (the silence is the hold watch's). Copies that then keep coming are one."""
    w = ClockWatch(periods=20)
    w.update(0, 0.002, 0, answered_ns=0)
    assert w.update(0, 0.002, 60 * MS, answered_ns=0) == Clock.REPEATED
    assert w.update(2 * MS, 0.002, 60 * MS + 100_000, answered_ns=0) == Clock.ADVANCED
    w.update(4 * MS, 0.002, 70 * MS, answered_ns=70 * MS)
    assert w.update(4 * MS, 0.002, 115 * MS, answered_ns=70 * MS) == Clock.REPEATED  # after a 45 ms silence
    verdicts = [w.update(4 * MS, 0.002, (115 + 10 * k) * MS, answered_ns=70 * MS) for k in range(1, 6)]
    assert verdicts == [Clock.REPEATED] * 3 + [Clock.FROZEN, Clock.REPEATED], verdicts
    assert w.reason.startswith("the robot's time stamp has not advanced for 40 ms"), w.reason


def test_the_period_allowance_is_the_robots_sample_time():
    w = ClockWatch(periods=20)
    w.update(0, 0.002, 0, answered_ns=0)
    assert w.update(0, 0.002, 39 * MS, answered_ns=0) == Clock.REPEATED
    assert w.update(0, 0.002, 40 * MS, answered_ns=0) == Clock.FROZEN


def test_a_changed_sample_time_and_a_clock_going_back_are_named():
    w = ClockWatch(periods=20)
    w.update(10 * MS, 0.001, 0, answered_ns=0)
    assert w.update(12 * MS, 0.002, MS, answered_ns=0) == Clock.RESAMPLED
    assert w.reason.startswith("the robot's sample time changed from 1 ms to 2 ms"), w.reason
    assert w.update(14 * MS, 0.002, 2 * MS, answered_ns=0) == Clock.ADVANCED
    assert w.update(4 * MS, 0.002, 3 * MS, answered_ns=0) == Clock.WENT_BACK
    assert w.reason == "the robot's clock went back 10.0 ms" and w.stamp_ns == 4 * MS


# -- the connection quality -----------------------------------------------------------------------------------

def test_the_quality_falling_is_told_at_good_warned_at_fair_and_disarms_at_poor():
    w = QualityWatch()
    assert w.update(Q.EXCELLENT) is None and w.note() == "" and w.disarm_reason() is None
    level, text = w.update(Q.GOOD)
    assert level == logging.INFO and "EXCELLENT -> GOOD (still sufficient for command mode)" in text
    assert w.note() == ("; the last state said FRI connection quality GOOD, down from EXCELLENT (the robot ends "
                        "commanding when it falls below GOOD)")
    level, text = w.update(Q.FAIR)
    assert level == logging.WARNING and "GOOD -> FAIR: insufficient for command mode" in text and w.warnings == 1
    assert w.disarm_reason() is None, "FAIR is warned about, not disarmed on (by default)"
    level, _ = w.update(Q.POOR)
    assert level == logging.WARNING and w.warnings == 2
    assert w.disarm_reason() == "FRI connection quality POOR (down from EXCELLENT): insufficient for command mode"
    assert w.update(Q.EXCELLENT)[0] == logging.INFO and w.fell_from is None and w.note() == ""
    assert QualityWatch(Q.FAIR).update(Q.FAIR)[0] == logging.WARNING


def test_disarm_at_fair_is_a_setting():
    w = QualityWatch(Q[LbrParams(disarm_at_quality="FAIR").disarm_at_quality])
    w.update(Q.EXCELLENT)
    w.update(Q.FAIR)
    assert w.disarm_reason().startswith("FRI connection quality FAIR")


# -- the commanded torque the robot reports -------------------------------------------------------------------

def _overlays(n: int, seed: int = 0) -> np.ndarray:
    """(n, 7) a smooth torque path [Nm]: what a controller sends."""
    t = np.arange(n)[:, None] * 0.002
    rng = np.random.default_rng(seed)
    return 5.0 * np.sin(2.0 * np.pi * rng.uniform(0.2, 1.0, 7) * t + rng.uniform(0, 6, 7))


def test_a_robot_that_rounds_the_overlay_shows_its_step_and_keeps_it_while_the_torque_stands():
    r = TorqueResolution(floor_nm=0.001, cap_nm=0.05)
    for tau in reported_commanded_torque(_overlays(300), 0.01, 0.0):
        r.update(tau)
    assert r.step_nm == pytest.approx(0.01) and r.tolerance_nm() == pytest.approx(0.00505)
    for _ in range(200):  # a held torque: the window holds one value, the step stays
        r.update(np.round(np.full(7, 1.234) / 0.01) * 0.01)
    assert r.tolerance_nm() == pytest.approx(0.00505)
    r.update(np.full(7, 1.2345))  # off the step: not the robot's any more
    assert math.isinf(r.step_nm) and r.tolerance_nm() == 0.001


def test_an_exact_echo_of_continuous_overlays_keeps_the_floor_and_a_coarse_step_is_capped():
    r = TorqueResolution(floor_nm=0.001, cap_nm=0.05)
    for tau in _overlays(300):
        r.update(tau)
    assert math.isinf(r.step_nm) and r.tolerance_nm() == 0.001
    coarse = TorqueResolution(floor_nm=0.001, cap_nm=0.05)
    for tau in reported_commanded_torque(_overlays(300), 0.5, 0.0):
        coarse.update(tau)
    assert coarse.step_nm == pytest.approx(0.5) and coarse.tolerance_nm() == 0.05
    few = TorqueResolution(floor_nm=0.001, cap_nm=0.05)
    for tau in (np.zeros(7), np.full(7, 0.5), np.zeros(7)):  # two values are no evidence of a step
        few.update(tau)
    assert math.isinf(few.step_nm)


def test_the_applied_check_matches_within_the_tolerance_and_says_how_close_it_came():
    w = AppliedWatch()
    for k in range(10):
        w.sent(np.full(7, 0.1 * k), k * MS)
    rounded = np.round(np.full(7, 0.9) / 0.01) * 0.01 + 0.004  # 4 mNm off the newest overlay
    assert w.old(rounded, 11 * MS, 0.005) and w.matched == 0, "no match at the 1 mNm floor: the oldest is 11 ms old"
    assert w.closest_nm == pytest.approx(0.004) and w.applied_ns is None
    assert w.stall_reason(1.0, 0.001) == (
        "commanded_torque matched none of our overlays in 1.0 s since arming (closest 0.0040 Nm off on A1, tolerance "
        "0.0010): the robot does not echo the overlay; set [lbr] check_applied = false or applied_tolerance_nm")
    assert not w.old(rounded, 11 * MS, 0.005, tol_nm=0.00505) and w.matched == 1 and w.applied_ns == 11 * MS
    assert w.stall_reason(1.2, 0.00505).startswith("no state on a recent overlay of ours for 1.2 s: the robot runs on "
                                                   "an old message")
    w.reset()
    assert w.applied_ns is None and math.isinf(w.closest_nm) and not w.sent_any


def test_states_are_judged_from_the_robots_first_echo_of_ours_since_arming():
    """A robot that runs on its own clock until our first answer reaches it (the lock-step peer's start, a CI cell
    under load: states_on_an_old_command +2 at arming) carries what the stack ran before for a few cycles past the
    stale limit: not judged. From its first echo of ours, a state on an overlay too old says no command applied;
    one that never echoes is the stall's to name after applied_stall_s."""
    def state(t_ms: int, tau) -> LbrState:
        z = np.zeros(7)
        return LbrState(0.002, int(SessionState.COMMANDING_ACTIVE), 0, 0, 2, 3, 2, t_ms * MS, z, z, z, z,
                        tau_commanded_nm=np.asarray(tau, float))

    check = AppliedCheck(0.001, 0.05, True, 0.005, 1.0)
    check.arm(0)
    check.sent.sent(np.full(7, 0.5), 0)  # our first answer, to the reading at 0 ms
    for t in range(2, 40, 2):  # 38 ms on the stack's own message, past the 13 ms limit
        assert check.update(state(t, np.zeros(7)), 0.002, True) is None and check.applying, t
    assert check.update(state(40, np.full(7, 0.5)), 0.002, True) is None and not check.applying, \
        "the first echo, of an answer 40 ms old"
    check.sent.sent(np.full(7, 0.6), 40 * MS)
    assert check.update(state(42, np.full(7, 0.6)), 0.002, True) is None and check.applying
    assert check.update(state(60, np.full(7, 0.6)), 0.002, True) is None and not check.applying, "18 ms on it"
    never = AppliedCheck(0.001, 0.05, True, 0.005, 1.0)
    never.arm(0)
    never.sent.sent(np.full(7, 0.5), 0)
    assert never.update(state(500, np.zeros(7)), 0.002, True) is None and never.applying
    assert never.update(state(1002, np.zeros(7)), 0.002, True).startswith("commanded_torque matched none")


# -- arming ---------------------------------------------------------------------------------------------------

def _state(quality: int = Q.EXCELLENT) -> LbrState:
    z = np.zeros(7)
    return LbrState(0.001, int(SessionState.COMMANDING_ACTIVE), 0, 0, 2, 3, 2, 5 * MS, z, z, z, z, z,
                    connection_quality=int(quality))


def test_arming_is_refused_below_good_and_on_a_frozen_clock():
    p, clock = LbrParams(open_loop=False), ClockWatch(20)
    kw = dict(layout_error="", names_ok=True, clock=clock, dq_rad_s=np.zeros(7))
    assert arming_refusal(_state(), p, **kw) is None
    assert arming_refusal(_state(Q.GOOD), p, **kw) is None
    assert arming_refusal(_state(Q.FAIR), p, **kw) == "FRI connection quality FAIR: insufficient for command mode"
    clock.update(5 * MS, 0.001, 0, answered_ns=0)
    for k in range(1, 6):
        clock.update(5 * MS, 0.001, 5 * k * MS, answered_ns=0)
    assert arming_refusal(_state(), p, **kw).startswith("the robot's time stamp has not advanced for 20 ms")


# -- the stand-in's failures ----------------------------------------------------------------------------------

def test_the_link_is_lost_for_a_while_and_the_quality_falls_a_level_a_step():
    link = FriLink(LbrPeerParams(link_lost_at_s=2.0, link_lost_for_s=0.35, quality_step_s=0.1))
    at = {t: (link.up(round(t * 1e9)), link.quality(round(t * 1e9)).name) for t in
          (1.999, 2.0, 2.099, 2.1, 2.2, 2.3, 2.349, 2.35)}
    assert at == {1.999: (True, "EXCELLENT"), 2.0: (False, "EXCELLENT"), 2.099: (False, "EXCELLENT"),
                  2.1: (False, "GOOD"), 2.2: (False, "FAIR"), 2.3: (False, "POOR"), 2.349: (False, "POOR"),
                  2.35: (True, "EXCELLENT")}, at
    for_good = FriLink(LbrPeerParams(link_lost_at_s=2.0))
    assert not for_good.up(10**12) and for_good.quality(10**12) == Q.POOR
    drop = FriLink(LbrPeerParams(quality_drop_at_s=3.0, quality_step_s=0.2))
    assert [drop.quality(round(t * 1e9)).name for t in (2.9, 3.0, 3.2, 3.4, 9.0)] == \
        ["EXCELLENT", "GOOD", "FAIR", "POOR", "POOR"]
    assert FriLink(LbrPeerParams()).up(10**15) and FriLink(LbrPeerParams()).quality(10**15) == Q.EXCELLENT


def test_the_robot_ends_commanding_after_the_quality_stays_below_good_for_the_set_time():
    s = RobotSession(LbrPeerParams(commanding_after_s=0.0, commanding_wait_s=0.0, quality_abort_after_s=0.5))
    assert s.advance(0) == SessionState.COMMANDING_ACTIVE
    assert s.advance(MS, Q.GOOD) == SessionState.COMMANDING_ACTIVE
    assert s.advance(2 * MS, Q.FAIR) == SessionState.COMMANDING_ACTIVE
    assert s.advance(501 * MS, Q.POOR) == SessionState.COMMANDING_ACTIVE
    assert s.advance(502 * MS, Q.POOR) == SessionState.MONITORING_WAIT
    assert s.advance(600 * MS, Q.EXCELLENT) == SessionState.MONITORING_READY, "over: the app must start again"
    at_once = RobotSession(LbrPeerParams(commanding_after_s=0.0, commanding_wait_s=0.0))
    at_once.advance(0)
    assert at_once.advance(MS, Q.FAIR) == SessionState.MONITORING_WAIT


def test_the_reported_commanded_torque_is_the_overlay_rounded_and_biased_as_set():
    tau = np.array([0.123, -0.456, 1.0, 0.0, 0.0049, -0.0051, 7.77777])
    np.testing.assert_array_equal(reported_commanded_torque(tau, 0.0, 0.0), tau)
    np.testing.assert_allclose(reported_commanded_torque(tau, 0.01, 0.0),
                               [0.12, -0.46, 1.0, 0.0, 0.0, -0.01, 7.78], atol=1e-12)
    np.testing.assert_allclose(reported_commanded_torque(tau, 0.0, 0.3), tau + 0.3)


def test_the_managers_missed_deadlines_are_skipped_and_counted():
    assert next_manager_deadline(1000, 1000, 1500) == (2000, 0)
    assert next_manager_deadline(1000, 1000, 4500) == (5000, 3)
