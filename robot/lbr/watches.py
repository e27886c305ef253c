"""Whether the robot is there, and how well: what the adapter watches in the states, as pure state.

Each watch is fed one state at a time (no network, numpy, SI units) and
answers to code of lbr_fri_ros2_stack (``rolling`` 218d723, ``humble``
cca24ae) or of the FRI client SDK (lbr-stack/fri ``ros2-fri-1.15``
0a5e17a); docs/real-robot.md has the table.

* :class:`ClockWatch`: liveness from the robot's clock. The stack opens its
  FRI socket without a receive timeout (app.cpp:7, ``UdpConnection()``;
  friUdpConnection.h:93-98: "0 = wait forever"), so when the robot's packets
  stop its FRI thread blocks in ``ClientApplication::step()``
  (friClientApplication.cpp:118, app.cpp:91-103) while the controller
  manager runs on: ``read()`` copies the last state every cycle
  (system_interface.cpp:291-297) and the state broadcaster publishes it
  (lbr_state_broadcaster.cpp:35-103), its time stamp and COMMANDING_ACTIVE
  included. States that keep arriving are no sign of life; a time stamp
  that advances is. The watch also says when the sample time changes or the
  clock goes back.
* :class:`QualityWatch`: the FRI connection quality every state carries
  (state.cpp:15, lbr_state_broadcaster.cpp:49-50; friClientIf.h:80-86: FAIR
  is "insufficient for command mode", GOOD "sufficient").
* :class:`TorqueResolution`: the step the robot reports its commanded
  torque in, learned from the values, so that the applied-command check
  (:class:`~robot.lbr.compensation.AppliedWatch`) tolerates a robot that
  does not echo the overlay bit for bit: the SDK documents
  ``getCommandedTorque()`` only as "the last commanded joint torques of the
  robot" (friLBRState.h:204-209).
* :class:`LinkWatch` and :class:`AppliedCheck`: the adapter's watches on
  the link as it runs them, state by state: the clock, the quality, frozen
  positions and the states' flow; whether the robot runs on our overlays.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from enum import IntEnum

import numpy as np

from .compensation import AppliedWatch, FreezeWatch
from .msgs import ConnectionQuality, LbrState, enum_name


class Clock(IntEnum):
    """What one state says of the robot's clock (:meth:`ClockWatch.update`)."""

    ADVANCED = 0
    """A newer time stamp: a new robot cycle."""
    REPEATED = 1
    """The newest time stamp again (a controller manager faster than the FRI cycle publishes a state twice)."""
    FROZEN = 2
    """The time stamp has not advanced for the allowed periods while states go on arriving: the FRI link is lost."""
    RESAMPLED = 3
    """A newer time stamp with another sample time than the states before it."""
    WENT_BACK = 4
    """An older time stamp than the newest seen: the robot's clock was set back (taken as the newest from now)."""


class ClockWatch:
    """Liveness from the robot's clock (module docstring).

    periods : how many of the robot's sample periods (of our own monotonic clock) states may go on arriving
    without their time stamp advancing, counted from our answer to the newest, before the link counts as lost.
    A robot that waits for its answer says its state again (the lock-step simulated stack does; the real stack
    never waits), so an unanswered stamp is not judged, and one answered late counts from the answer.

    "Keep arriving" means without a silence as long as the allowance between two of them: a lost link has the
    manager re-publish every cycle (10 ms at most, lbr_controllers.yaml:5), while a manager thread the host
    stalled publishes the state it last read once more when it runs again, then a new one. Such a copy after a
    silence starts the count again; the silence itself is the hold watch's (``hold_timeout_s``).
    """

    def __init__(self, periods: int) -> None:
        self.periods = periods
        self.stamp_ns: int | None = None  # the newest time stamp [robot ns]
        self.sample_time_s: float | None = None
        self.frozen = False  # the stamp has been judged frozen and has not advanced since
        self.frozen_ns = 0  # how long [our ns] the newest stamp has been arriving, as of the last state
        self.reason = ""
        self._since_ns = 0  # when [our ns] the newest stamp first arrived (again after a silence)
        self._last_ns = 0  # when [our ns] the newest stamp last arrived

    def update(self, stamp_ns: int, sample_time_s: float, arrival_ns: int, answered_ns: int | None) -> Clock:
        """One state: its time stamp [robot ns], sample time [s], arrival [ns, our monotonic clock]; ``answered_ns``:
        when [ns, our clock] we first answered the newest stamp (None: not yet). :attr:`reason` says why for the
        last FROZEN, RESAMPLED or WENT_BACK."""
        if self.stamp_ns is not None and self.sample_time_s is not None and stamp_ns == self.stamp_ns:
            limit_ns = self.periods * self.sample_time_s * 1e9
            if arrival_ns - self._last_ns >= limit_ns:
                self._since_ns = arrival_ns  # a copy after a silence: the count starts again
            self._last_ns = arrival_ns
            self.frozen_ns = arrival_ns - self._since_ns
            if self.frozen or answered_ns is None or arrival_ns - max(answered_ns, self._since_ns) < limit_ns:
                return Clock.REPEATED  # judged once an episode: FROZEN is returned for the first state past it
            self.frozen = True
            self.reason = (f"the robot's time stamp has not advanced for {self.frozen_ns / 1e6:.0f} ms (over "
                           f"{self.periods} periods of {self.sample_time_s * 1e3:g} ms) while its states keep "
                           "arriving: the FRI link is lost (the stack waits for ever on its FRI socket and "
                           "re-publishes its last state)")
            return Clock.FROZEN
        old_stamp, old_sample = self.stamp_ns, self.sample_time_s
        self.stamp_ns, self.sample_time_s = stamp_ns, sample_time_s
        self._since_ns, self._last_ns, self.frozen, self.frozen_ns = arrival_ns, arrival_ns, False, 0
        if old_stamp is not None and stamp_ns < old_stamp:
            self.reason = f"the robot's clock went back {(old_stamp - stamp_ns) / 1e6:.1f} ms"
            return Clock.WENT_BACK
        if old_sample is not None and sample_time_s != old_sample:
            self.reason = (f"the robot's sample time changed from {old_sample * 1e3:g} ms to {sample_time_s * 1e3:g} "
                           "ms (the application restarted with another send period?)")
            return Clock.RESAMPLED
        return Clock.ADVANCED


def quality_name(value: int | None) -> str:
    """The :class:`ConnectionQuality` name of ``value`` (``unknown(v)`` for another number, ``none`` for None)."""
    return enum_name(ConnectionQuality, value)


class QualityWatch:
    """The FRI connection quality of the states, and what to say about it.

    disarm_at : the quality at or below which the adapter disarms (POOR by default; FAIR also possible). The
    robot ends commanding when the quality falls below GOOD (friClientIf.h:74,83: FAIR is insufficient for
    command mode), so a fall is warned about at FAIR and named when commanding ends.
    """

    def __init__(self, disarm_at: int = ConnectionQuality.POOR) -> None:
        self.disarm_at = int(disarm_at)
        self.quality: int | None = None
        self.fell_from: int | None = None  # the quality before the current fall began (None: not falling)
        self.warnings = 0  # falls into FAIR or below

    def update(self, quality: int) -> tuple[int, str] | None:
        """The state's quality; (logging level, line) when it changed, else None."""
        old, self.quality = self.quality, int(quality)
        if old == quality or (old is None and quality >= ConnectionQuality.GOOD):
            return None
        if old is None:
            self.warnings += 1
            return logging.WARNING, (f"FRI connection quality {quality_name(quality)}: insufficient for command mode")
        if quality > old:
            self.fell_from = None if quality >= ConnectionQuality.EXCELLENT else self.fell_from
            return logging.INFO, f"FRI connection quality up: {quality_name(old)} -> {quality_name(quality)}"
        if self.fell_from is None:
            self.fell_from = old
        if quality > ConnectionQuality.FAIR:
            return logging.INFO, (f"FRI connection quality down: {quality_name(old)} -> {quality_name(quality)} "
                                  "(still sufficient for command mode)")
        self.warnings += 1
        return logging.WARNING, (f"FRI connection quality down: {quality_name(old)} -> {quality_name(quality)}: "
                                 "insufficient for command mode, the robot ends commanding below GOOD")

    def disarm_reason(self) -> str | None:
        """Why to disarm for the quality (at or below :attr:`disarm_at`), or None."""
        if self.quality is None or self.quality > self.disarm_at:
            return None
        return (f"FRI connection quality {quality_name(self.quality)} (down from {quality_name(self.fell_from)}): "
                "insufficient for command mode")

    def note(self) -> str:
        """What the quality says when commanding ends: empty while it is EXCELLENT or unknown."""
        if self.quality is None or self.quality >= ConnectionQuality.EXCELLENT:
            return ""
        fell = f", down from {quality_name(self.fell_from)}" if self.fell_from is not None else ""
        return (f"; the last state said FRI connection quality {quality_name(self.quality)}{fell} (the robot ends "
                "commanding when it falls below GOOD)")


class TorqueResolution:
    """The step [Nm] the robot reports its commanded torque in, learned from the values.

    The candidate is the smallest non-zero change of any joint's value between consecutive states; it is taken as
    the robot's step once every value of the last ``window`` states is a whole number of it and they hold at least
    ``min_distinct`` distinct values, and kept until a value is not (a robot that rounds the overlay shows its step
    as soon as a joint moves by one; one that echoes continuous overlays never fits a step, and the tolerance
    stays at its floor).

    floor_nm, cap_nm : the tolerance :meth:`tolerance_nm` gives is within [floor_nm, cap_nm].
    """

    def __init__(self, floor_nm: float, cap_nm: float, window: int = 64, min_distinct: int = 8) -> None:
        self.floor_nm = floor_nm
        self.cap_nm = cap_nm
        self.min_distinct = min_distinct
        self.candidate_nm = math.inf
        self.step_nm = math.inf  # the step taken as the robot's (inf: none fits)
        self._values: deque[np.ndarray] = deque(maxlen=window)

    def update(self, tau_commanded: np.ndarray | None) -> None:
        """A state's commanded torque (7,) [Nm] (None: the state has none)."""
        if tau_commanded is None:
            return
        if self._values:
            d = np.abs(tau_commanded - self._values[-1])
            d = d[d > 1e-12]
            if d.size:
                self.candidate_nm = min(self.candidate_nm, float(d.min()))
        self._values.append(np.array(tau_commanded, float))
        if math.isfinite(self.step_nm) and not _whole(self._values[-1] / self.step_nm):
            self.step_nm = math.inf  # a value off the step: not the robot's
        if self.candidate_nm < self.step_nm and self._fits(self.candidate_nm):
            self.step_nm = self.candidate_nm

    def _fits(self, step: float) -> bool:
        if not math.isfinite(step):
            return False
        v = np.array(self._values) / step
        return _whole(v) and np.unique(np.round(v)).size >= self.min_distinct

    def tolerance_nm(self) -> float:
        """Half the step (the robot rounds to the nearest one) with 1 % to spare, within [floor, cap] [Nm]."""
        half = 0.505 * self.step_nm if math.isfinite(self.step_nm) else self.floor_nm
        return min(max(half, self.floor_nm), self.cap_nm)


class LinkWatch:
    """The adapter's watches on the link, fed each state: whether the robot is there and runs as the arm.

    clock : :class:`ClockWatch` (``frozen_stamp_periods``); quality : :class:`QualityWatch` (``disarm_at_quality``);
    freeze : :class:`~robot.lbr.compensation.FreezeWatch` (``frozen_after_s``: positions still under a changing
    overlay); last_state_ns : when [monotonic ns] the newest state arrived, a re-sent one too (None: none yet);
    robot_waits : the server runs lock-step (the robot's clock waits for our answers, so it is not judged);
    answered : (the robot time [ns] of the reading our last message answered, when [monotonic ns] we first did).
    """

    def __init__(self, frozen_stamp_periods: int, disarm_at_quality: int, frozen_after_s: float) -> None:
        self.clock = ClockWatch(frozen_stamp_periods)
        self.quality = QualityWatch(disarm_at_quality)
        self.freeze = FreezeWatch(frozen_after_s)
        self.last_state_ns: int | None = None
        self.robot_waits = False
        self.answered = (-1, 0)

    def answer(self, robot_time_ns: int) -> None:
        """A message went out answering the reading of robot time ``robot_time_ns``."""
        if self.answered[0] != robot_time_ns:
            self.answered = (robot_time_ns, time.monotonic_ns())

    def state(self, st: LbrState, arrival_ns: int) -> Clock:
        """A state arrived at ``arrival_ns`` [monotonic ns]: what it says of the robot's clock
        (:meth:`ClockWatch.update`, its :attr:`ClockWatch.reason`)."""
        self.last_state_ns = time.monotonic_ns()  # a re-sent state too: the robot is there, waiting
        answered = self.answered[1] if self.answered[0] == self.clock.stamp_ns and not self.robot_waits else None
        return self.clock.update(st.stamp_ns, st.sample_time_s, arrival_ns, answered)

    def silence(self, limit_s: float) -> str | None:
        """Why commanding must end when no state has come for over ``limit_s`` [s] (the stack or the bridge gone),
        or None."""
        if self.last_state_ns is None:
            return None
        silent_s = (time.monotonic_ns() - self.last_state_ns) * 1e-9
        if silent_s <= limit_s:
            return None
        return (f"no robot state for {silent_s * 1e3:.0f} ms (the stack exits when the robot leaves "
                f"COMMANDING_ACTIVE: launch it again; or the bridge is gone){self.quality.note()}")


class AppliedCheck:
    """Whether the robot runs on a recent overlay of ours, within the robot's learned resolution.

    sent : :class:`~robot.lbr.compensation.AppliedWatch`, the overlays sent; resolution : :class:`TorqueResolution`
    (``applied_tolerance_nm`` to ``applied_tolerance_max_nm``); enabled : ``check_applied``; stale_limit_s : how old
    [s] an answer may be before the server holds; stall_s : ``applied_stall_s``, how long [s, robot time] an armed
    adapter may see no state on a recent overlay; applying : the newest state's verdict; armed_ns : the robot time
    [ns] at arming. States are judged from the robot's first echo of an overlay of ours since arming.
    """

    def __init__(self, tol_nm: float, tol_max_nm: float, enabled: bool, stale_limit_s: float,
                 stall_s: float) -> None:
        self.sent = AppliedWatch(tol_nm=tol_nm)
        self.resolution = TorqueResolution(tol_nm, tol_max_nm)
        self.enabled = enabled
        self.stale_limit_s = stale_limit_s
        self.stall_s = stall_s
        self.applying = True
        self.armed_ns = 0

    def arm(self, t_ns: int) -> None:
        """Armed at robot time ``t_ns``: what the robot ran on before is not judged."""
        self.armed_ns = t_ns
        self.sent.reset()

    def update(self, st: LbrState, period_s: float, armed: bool) -> str | None:
        """The state ``st`` (state period ``period_s`` [s]): sets :attr:`applying`; why to disarm, armed and no state
        on a recent overlay for :attr:`stall_s`, or None."""
        self.resolution.update(st.tau_commanded_nm)
        checking = armed and self.enabled
        # answer, manager cycle, FRI cycles applying and reporting it, manager cycle publishing: 2 periods of each
        old = checking and self.sent.old(st.tau_commanded_nm, st.stamp_ns,
                                         self.stale_limit_s + 2.0 * (period_s + st.sample_time_s),
                                         self.resolution.tolerance_nm())
        # judged from the robot's first echo of ours since arming: before it the states carry what the stack ran
        # before (a robot running on its own clock until our first answer, the lock-step peer's start), and one
        # that never echoes is the stall's to name
        self.applying = not (old and self.sent.matched > 0)
        if not (checking and self.sent.sent_any):
            return None
        since_ns = st.stamp_ns - (self.sent.applied_ns if self.sent.applied_ns is not None else self.armed_ns)
        if since_ns * 1e-9 > self.stall_s:
            return self.sent.stall_reason(since_ns * 1e-9, self.resolution.tolerance_nm())
        return None


def _whole(v: np.ndarray) -> bool:
    """Whether every value of ``v`` is a whole number (to 1e-4: a rounded value divided by its step)."""
    return bool(np.all(np.abs(v - np.round(v)) <= 1e-4))
