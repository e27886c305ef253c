"""The adapter's liveness and link watches over real Zenoh, the stack's states put by hand.

The harness is :class:`tests.test_lbr_adapter.Cell`: the robot server with an
:class:`~robot.lbr.adapter.LbrPort` on a thread, "the stack" a raw Zenoh
session putting CDR ``LBRState`` where zenoh-bridge-ros2dds would and
recording every ``LBRTorqueCommand``, "the controller" a ServiceNode. Each
failure the real stack can show: its FRI thread blocked on a lost link while
its controller manager re-publishes the last state (time stamp and
COMMANDING_ACTIVE included), a changed sample time, the connection quality
falling before the robot ends commanding.
"""

from __future__ import annotations

import time

import numpy as np

from robot.lbr.msgs import ConnectionQuality, SessionState, encode_state

from .test_lbr_adapter import Q0, Cell, lbr_state
from .zenoh_helpers import wait_for

Q = ConnectionQuality


def _republish(cell: Cell, stamp: int, count: int, period_s: float = 0.001, **kw) -> None:
    """The controller manager re-publishing the state of robot time ``stamp``, ``count`` times, every ``period_s``
    of our clock."""
    raw = encode_state(lbr_state(Q0, stamp, **kw))
    for _ in range(count):
        time.sleep(period_s)
        cell.stack.state_pub.put(raw)


def test_states_that_keep_coming_with_a_frozen_stamp_disarm_and_arming_waits_for_the_clock():
    """The stack's FRI thread blocked on its socket (no receive timeout): the manager goes on publishing the last
    state at 1 kHz. 20 periods (20 ms of our clock) after the last stamp first came, the adapter disarms, sends the
    hold (the stack keeps it for when the link is back) and says why; no RobotState for the repeats; an arm
    request is refused until the stamp advances again."""
    with Cell() as cell:
        cell.armed()
        s = cell.step(Q0)
        cell.answer(s, np.ones(7))
        n = len(cell.stack.commands)
        _republish(cell, cell.t_ns, 60)
        st = cell.wait_status(lambda m: "armed=False" in m.detail, "disarmed on the frozen clock")
        assert "why=\"the robot's time stamp has not advanced for" in st.detail, st.detail
        assert "while its states keep arriving: the FRI link is lost" in st.detail, st.detail
        assert st.counters["frozen_stamps"] == 1 and st.counters["states_repeated"] >= 5, st.counters
        _, jp, tau = cell.stack.commands[n]
        assert jp.tolist() == Q0.tolist() and not np.any(tau), "the hold, at the last measured pose"
        assert cell.states.get(0.05) is None, "no RobotState for a repeated stamp"
        refused = cell.request(True, "arm_refused")
        assert "arming refused: the robot's time stamp has not advanced" in refused.detail, refused.detail
        cell.answer(cell.step(Q0), np.zeros(7), sent=False)  # the link is back: a new stamp
        assert "armed=True" in cell.request(True, "arms").detail


def test_a_frozen_stamp_is_judged_from_our_answer_not_from_a_robot_waiting_for_it():
    """A state said again before we answered it (the lock-step stand-in waits for its answer) is not a lost link;
    nor are a few repeats of an answered one (a manager faster than the FRI cycle)."""
    with Cell() as cell:
        cell.armed()
        s = cell.step(Q0)
        received = cell.port.counts["states_received"]
        _republish(cell, cell.t_ns, 40)  # unanswered: 40 ms of repeats
        cell.answer(s, np.ones(7))
        _republish(cell, cell.t_ns, 5, period_s=0.0)  # answered: 5 more at once (a host stall between is a gap)
        cell.answer(cell.step(Q0), np.ones(7))
        st = cell.wait_status(lambda m: m.counters.get("states_received", 0) >= received + 46, "the repeats come")
    assert "armed=True" in st.detail and "frozen_stamps" not in st.counters, st
    assert st.counters["states_repeated"] >= 1, st.counters


def test_a_lock_step_robot_that_waits_for_us_is_not_judged_by_its_clock():
    """In lock-step the robot's clock stands while the cell is slow: the stand-in re-sends its state until its
    answer arrives, and a starved stand-in re-sends it after our answer too. No lost link is judged then."""
    with Cell(server={"mode": "lockstep"}) as cell:
        cell.armed()
        cell.answer(cell.step(Q0), np.ones(7))
        received = cell.port.counts["states_received"]
        _republish(cell, cell.t_ns, 60)
        st = cell.wait_status(lambda m: m.counters.get("states_received", 0) >= received + 60, "the repeats come")
    assert "armed=True" in st.detail and "frozen_stamps" not in st.counters, st


def test_a_changed_sample_time_disarms():
    with Cell() as cell:
        cell.armed()
        cell.answer(cell.step(Q0), np.ones(7))
        cell.step(Q0, dt_s=0.002)
        st = cell.wait_status(lambda m: "armed=False" in m.detail, "disarmed on the sample time")
    assert "why=\"the robot's sample time changed from 1 ms to 2 ms" in st.detail, st.detail
    assert st.counters["sample_time_changes"] == 1 and st.counters["disarms"] == 1, st.counters


def test_the_connection_quality_is_in_the_status_warned_at_fair_and_named_when_commanding_ends():
    """GOOD and FAIR while commanding: in the status, FAIR counted as a warning, still armed (the robot decides when
    to end). The robot then ends commanding and the stack exits (system_interface.cpp:307-318): no more states;
    the disarm on the silence names the last quality."""
    with Cell({"hold_timeout_s": 0.2}) as cell:
        cell.armed()
        cell.answer(cell.step(Q0, connection_quality=Q.GOOD), np.ones(7))
        st = cell.wait_status(lambda m: "quality=GOOD" in m.detail, "GOOD in the status")
        assert st.counters["connection_quality"] == 2 and st.counters["connection_quality_warnings"] == 0
        cell.answer(cell.step(Q0, connection_quality=Q.FAIR), np.ones(7))
        st = cell.wait_status(lambda m: "quality=FAIR" in m.detail, "FAIR in the status")
        assert "armed=True" in st.detail and st.counters["connection_quality_warnings"] == 1, st
        st = cell.wait_status(lambda m: "armed=False" in m.detail, "disarmed on the silence", 5.0)
    assert "why='no robot state for" in st.detail, st.detail
    assert "the last state said FRI connection quality FAIR, down from EXCELLENT (the robot ends commanding when it" \
        in st.detail, st.detail


def test_a_poor_connection_disarms_at_once_and_arming_needs_good():
    with Cell() as cell:
        cell.armed()
        cell.answer(cell.step(Q0), np.ones(7))
        n = len(cell.stack.commands)
        s = cell.step(Q0, connection_quality=Q.POOR)
        wait_for(lambda: len(cell.stack.commands) > n, 5.0, "the hold")
        cell.answer(s, np.ones(7), sent=False)
        st = cell.wait_status(lambda m: "armed=False" in m.detail, "disarmed at POOR")
        assert "why='FRI connection quality POOR (down from EXCELLENT)" in st.detail, st.detail
        assert st.counters["quality_disarms"] == 1 and st.counters["connection_quality"] == 0, st.counters
        cell.step(Q0, connection_quality=Q.FAIR, session=SessionState.MONITORING_WAIT)
        refused = cell.request(True, "arm_refused")
    assert "arming refused: FRI connection quality FAIR: insufficient for command mode" in refused.detail, refused
