"""What the adapter undoes of the stack: its torque filter, its PID and the robot's joint spring, a frozen stream.

Pure state on numpy arrays (joints A1..A7, SI units), the stack's code
cited by file and line (lbr_fri_ros2_stack ``rolling`` 218d723):

* :func:`filter_alpha` and :class:`TorqueUnfilter`: the stack low-passes
  measured and external torque (state.cpp:18,26, filters.cpp:23-28,
  ``y = a x + (1 - a) y_prev`` each FRI cycle); from two consecutive
  states the raw torque is ``x = (y - (1 - a)^n y_prev) / (1 - (1 - a)^n)``
  for a torque that held over the n cycles between them (n = 1 exactly).
* :class:`JointSpring`: the robot holds joint impedance at stiffness K
  (LBRServer.java: 200 Nm/rad) towards the position the stack's PID makes
  of the message's ``joint_position`` (``c += p (target - q)`` per FRI
  cycle, filters.cpp:56-62, torque_command.cpp:33-37). The adapter steers
  that position onto the arm (``target = q + (share / p) (q - c)``: each
  application moves ``c`` by ``share`` of its distance to ``q``, at most
  ``speed`` faster than the arm moves: the robot damps ``dc/dt - dq``) and takes
  the rest of the spring, ``K (c_next - q)``, off the overlay, so the
  controller's torque is what reaches the joints. ``c`` is the state's
  ``commanded_joint_position`` (FRI 1) or, where the state lacks it (FRI 2),
  the same PID run on the states the adapter sees, with the targets the
  robot ran on: a state's ``commanded_torque`` is the overlay of the FRI
  cycle before it (the stand-in's ``reported_commanded_torque``), and it
  names the message, hence the target, the PID had in that cycle. Only the
  newest state's own cycle is guessed (the message sent before our newest)
  and settled at the next state, so a guess never accumulates: with a fixed
  guess for every cycle, an answer that reached a free-running manager in
  time for the next FRI cycle (or one cycle later than guessed) was
  integrated as the wrong target, and the mirror walked away from the
  stack's command (1.5 mrad on A4 in a real-time FRI 2 cell under load, the
  spring's error taking 1.8 N off a 10 N press).
* :class:`AppliedWatch`: the overlays sent, and whether the torque a state
  says the robot applied (``commanded_torque``) is a recent one of them,
  within a tolerance the robot's own resolution may widen
  (:class:`~robot.lbr.watches.TorqueResolution`); the stack re-applies the
  last message it got for as long as it runs
  (lbr_torque_command_controller.cpp:42-55), so when ours stop reaching it
  the robot runs on an old one. It keeps when a state was last on a recent
  overlay and how close the robot's value came, so that a robot that never
  echoes is named, not stalled on.
* :class:`FreezeWatch`: measured positions that do not change at all while
  the overlay does are not a robot's (the stack's ``open_loop`` publishes
  its own command as measured, async_client.cpp:82-85).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np


def filter_alpha(cutoff_hz: float, sample_time_s: float) -> float:
    """The stack's smoothing factor (filters.cpp:23-28) for a cutoff [Hz] at a sample time [s]."""
    c = math.cos(2.0 * math.pi * sample_time_s * cutoff_hz)
    return c - 1.0 + math.sqrt(max(c * c - 4.0 * c + 3.0, 0.0))


class TorqueUnfilter:
    """The raw torque (n,) [Nm] behind the stack's filtered one, from consecutive states.

    cutoff_hz : the stack's cutoff for this torque; max_cycles : a longer gap between states (FRI cycles)
    restarts the estimate (the filtered value is passed on until two states are close enough).
    """

    def __init__(self, cutoff_hz: float, n: int = 7, max_cycles: int = 20) -> None:
        self.cutoff_hz = cutoff_hz
        self.max_cycles = max_cycles
        self.passed_filtered = 0  # states whose torque went on filtered (first, gap)
        self._y = np.zeros(n)
        self._t_ns: int | None = None
        self.x = np.zeros(n)

    def alpha(self, sample_time_s: float) -> float:
        return filter_alpha(self.cutoff_hz, sample_time_s)

    def update(self, y: np.ndarray, t_ns: int, sample_time_s: float) -> np.ndarray:
        """The raw torque at robot time ``t_ns`` from the filtered ``y``; :attr:`x` (reused)."""
        a = self.alpha(sample_time_s)
        cycles = round((t_ns - self._t_ns) * 1e-9 / sample_time_s) if self._t_ns is not None else 0
        if a >= 1.0:
            self.x[:] = y
        elif 1 <= cycles <= self.max_cycles and a > 1e-9:
            keep = (1.0 - a) ** cycles
            np.subtract(y, keep * self._y, out=self.x)
            self.x /= 1.0 - keep
        else:
            self.x[:] = y
            self.passed_filtered += 1
        self._y[:] = y
        self._t_ns = t_ns
        return self.x


class JointSpring:
    """The robot's joint spring and the stack's PID, as the adapter knows them (module docstring).

    stiffness : (7,) [Nm/rad] the app's joint stiffness; pid_p : the stack's ``pid_p``; share : how much of
    ``q - c`` one message closes (0 < share <= 1); speed_rad_s : how much faster than the arm that may move ``c``
    [rad/s] (0: no bound).
    """

    #: FRI 2: the messages kept for the robot's echo to name (a message older than this is not named)
    RING = 32

    def __init__(self, stiffness: np.ndarray, pid_p: float, share: float, speed_rad_s: float = 0.0) -> None:
        self.K = np.asarray(stiffness, float)
        self.p = pid_p
        self.share = share
        self.speed = speed_rad_s
        self.c: np.ndarray | None = None  # the stack's joint position command, as last known or mirrored
        self._targets: deque[np.ndarray] = deque(maxlen=2)  # the last two targets sent, oldest first
        self._t_ns: int | None = None
        # FRI 2: a ring of the last RING messages sent, message number i in row i % RING: the robot time of the
        # state it answered [ns], its target and overlay; _count sent since the reset; the mirror settled up to
        # the FRI cycle of robot time _settled_ns; the newest state's joint position
        self._sent_ns = [0] * self.RING
        self._sent_target = np.zeros((self.RING, 7))
        self._sent_overlay = np.zeros((self.RING, 7))
        self._count = 0
        self._settled: np.ndarray | None = None
        self._settled_ns = 0
        self._q: np.ndarray | None = None
        self._named_at = -1  # the number of the message the last echo named (-1: none)
        self.lag_ns: int | None = None  # from a state to the FRI cycle that applies its answer, as the echoes say
        self.echoes_named = 0  # FRI 2 states whose commanded torque named a message kept (its target settled)
        self.echoes_missed = 0  # ... named none within the tolerance (the guess settled instead)

    def reset(self, c: np.ndarray, t_ns: int) -> None:
        """Start from a known stack command ``c`` (7,) [rad] at robot time ``t_ns`` (arming)."""
        self.c = np.array(c, float)
        self._targets.clear()
        self._count = 0
        self._named_at = -1
        self._t_ns = t_ns
        self._settled, self._settled_ns = self.c.copy(), t_ns

    def observe(self, q: np.ndarray, t_ns: int, sample_time_s: float, c_reported: np.ndarray | None,
                tau_commanded: np.ndarray | None = None, tol_nm: float = 1e-3) -> None:
        """A new state: the reported command (FRI 1), or the PID run over the FRI cycles since the last state (FRI 2).

        FRI 2: the state's commanded torque ``tau_commanded`` (7,) [Nm] is the robot's overlay in the FRI cycle
        before it; the message sent with that overlay (within ``tol_nm``, the closest, the newest of equals) had
        its target in that cycle, and the robot time from the state it answered to that cycle is the lag
        (:attr:`lag_ns`). The cycles up to that one are settled, skipped states' joint positions interpolated and
        their targets those the lag gives (never older than the last named, never newer than this one); this
        state's own cycle runs the target the lag gives, settled at the next state, so a wrong guess never
        accumulates. Before any echo names one of ours the lag is two FRI cycles: a message reaches the stack at
        the manager's next cycle and the robot at the FRI cycle after it (taking the newest instead ran ``c`` ahead
        by ``p`` times the target's travel: 13 mrad, 2.6 Nm of spring, after 0.13 rad of A2). Without an echo that
        names one of ours (none given, a robot that does not echo, a message older than the ring) that guess
        settles every cycle."""
        q = np.asarray(q, float)
        if c_reported is not None:
            self.c = np.array(c_reported, float)
        elif self.c is None:
            self.c = q.copy()
        elif len(self._targets) == 2 and self._t_ns is not None:
            self._mirror(q, t_ns, round(sample_time_s * 1e9), tau_commanded, tol_nm)
        self._t_ns = t_ns
        self._q = q.copy()

    def _mirror(self, q: np.ndarray, t_ns: int, period_ns: int, tau_commanded: np.ndarray | None,
                tol_nm: float) -> None:
        t_last, c = self._t_ns, self.c
        assert t_last is not None and c is not None, "mirrored before a state"  # observe's last branch
        named = self._named(tau_commanded, tol_nm) if self._settled is not None else None
        if named is None:  # the guess for every cycle since the last state
            if tau_commanded is not None:
                self.echoes_missed += 1
            cycles = max(round((t_ns - t_last) / period_ns), 0)
            for _ in range(min(cycles, 50)):
                c += self.p * (self._targets[0] - q)  # in place: self.c
            self._settled, self._settled_ns, self._named_at = c.copy(), t_ns, -1
            return
        self.echoes_named += 1
        last = t_ns - period_ns  # the cycle the echo names
        self.lag_ns = last - self._sent_ns[named % self.RING]
        lo = max(self._named_at, self._count - self.RING, 0)
        span = max(round((t_ns - t_last) / period_ns), 1)  # cycles from the last state to this one
        q_prev = self._q if self._q is not None else q
        t_cycle = self._settled_ns + period_ns
        for _ in range(min(round((last - self._settled_ns) / period_ns), 50)):
            i = round((t_cycle - t_last) / period_ns)  # from the last state's cycle
            target = self._sent_target[named % self.RING] if t_cycle >= last else self._lagged(t_cycle, lo, named)
            self._settled += self.p * (target - (q_prev + (q - q_prev) * (min(max(i, 0), span) / span)))
            t_cycle += period_ns
        self._settled_ns, self._named_at = last, named
        self.c = self._settled + self.p * (self._lagged(t_ns, named, self._count - 1) - q)

    def _lagged(self, t_cycle_ns: int, lo: int, hi: int) -> np.ndarray:
        """The target the robot ran on in the FRI cycle of robot time ``t_cycle_ns``, as the lag says: the newest of
        the messages number ``lo..hi`` that answered a state at least :attr:`lag_ns` before (message ``lo`` if
        none)."""
        lag = self.lag_ns if self.lag_ns is not None else 0
        for i in range(hi, lo, -1):
            if self._sent_ns[i % self.RING] <= t_cycle_ns - lag:
                return self._sent_target[i % self.RING]
        return self._sent_target[lo % self.RING]

    def _named(self, tau_commanded: np.ndarray | None, tol_nm: float) -> int | None:
        """The number of the message kept whose overlay is closest to ``tau_commanded`` (the newest of equals),
        within ``tol_nm``; None otherwise."""
        if tau_commanded is None or self._count == 0:
            return None
        numbers = np.arange(self._count - 1, max(self._count - self.RING, 0) - 1, -1)  # newest first
        d = np.max(np.abs(self._sent_overlay[numbers % self.RING] - tau_commanded), axis=1)
        best = int(np.argmin(d))
        return int(numbers[best]) if d[best] <= tol_nm else None

    def command(self, q: np.ndarray, tau_nm: np.ndarray, dq: np.ndarray | None = None,
                sample_time_s: float = 0.0, cycles: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(joint_position target (7,), overlay (7,)) that make the joints see ``tau_nm`` at ``q``.

        The step of ``c`` is ``share (q - c)``, bounded to ``(dq +- speed) cycles sample_time_s`` when the arm's
        velocity ``dq`` (7,) [rad/s] is given: the robot's joint damping acts on ``dc/dt - dq``, so a step of ``c``
        is a torque impulse (after a gap in the messages the stack's PID has run ``c`` off the arm; closing a share
        of that in one cycle kicked a joint with D dc/dt, 180 Nm on A1 for 6 ms in the simulated stack).

        ``cycles`` : the FRI cycles the message will be applied for (a controller manager slower than the FRI
        cycle hands the same message to the PID each cycle until its next one): the step is spread over them,
        ``target = q + step / (p cycles)``, and the overlay takes off the spring's mean over them,
        ``K (c + step (cycles + 1) / (2 cycles) - q)`` (one cycle: ``K (c + step - q)``)."""
        c = self.c if self.c is not None else q
        n = max(int(cycles), 1)
        step = self.share * (q - c)
        if dq is not None and self.speed > 0 and sample_time_s > 0:
            drift = dq * sample_time_s * n
            room = self.speed * sample_time_s * n
            step = np.clip(step, drift - room, drift + room)
        target = q + step / (self.p * n) if self.p > 0 else np.array(q, float)
        overlay = tau_nm - self.K * (c + step * (n + 1) / (2 * n) - q)
        self._targets.append(target)
        self._sent_one(target, overlay)
        return target, overlay

    def hold(self, target: np.ndarray) -> None:
        """A hold (``target``, zero overlay) went out: the mirror follows it."""
        self._targets.append(np.array(target, float))
        self._sent_one(self._targets[-1], np.zeros_like(self._targets[-1]))

    def _sent_one(self, target: np.ndarray, overlay: np.ndarray) -> None:
        """A message went out answering the newest state (its robot time the message's)."""
        row = self._count % self.RING
        self._sent_ns[row] = self._t_ns if self._t_ns is not None else 0
        self._sent_target[row] = target
        self._sent_overlay[row] = overlay
        self._count += 1


class AppliedWatch:
    """The last ``n`` overlays sent, each with the robot time [ns] of the reading it answered (a ring).

    tol_nm : a state's commanded torque is an overlay sent when no joint differs by more than this [Nm] (a call may
    give its own: the robot's resolution, :class:`~robot.lbr.watches.TorqueResolution`).
    """

    def __init__(self, n: int = 32, tol_nm: float = 1e-3) -> None:
        self.tol_nm = tol_nm
        self._overlay = np.zeros((n, 7))
        self._t_ns = np.zeros(n, dtype=np.int64)
        self._n = 0
        self.matched = 0  # states whose commanded torque was one of the overlays kept, since the reset
        self.applied_ns: int | None = None  # robot time of the last state on a recent overlay, since the reset
        self.closest_nm = math.inf  # the smallest distance of a state's commanded torque to an overlay kept
        self.closest_joint = 0  # ... on this joint (0-based), since the reset

    def reset(self) -> None:
        """Forget what was sent (arming: what the robot ran on before is not judged)."""
        self._n = 0
        self.matched = 0
        self.applied_ns = None
        self.closest_nm = math.inf

    @property
    def sent_any(self) -> bool:
        return self._n > 0

    def sent(self, overlay: np.ndarray, t_ns: int) -> None:
        """An overlay (7,) [Nm] went out answering the reading of robot time ``t_ns``."""
        row = self._n % len(self._t_ns)
        self._overlay[row] = overlay
        self._t_ns[row] = t_ns
        self._n += 1

    def old(self, tau_commanded: np.ndarray | None, t_ns: int, max_age_s: float, tol_nm: float | None = None) -> bool:
        """True when the robot ran (state of robot time ``t_ns``, commanded torque (7,) [Nm]) on an overlay sent for
        a reading more than ``max_age_s`` older, or on none of those kept while they reach back that far. False
        before anything is sent or without the commanded torque."""
        n = min(self._n, len(self._t_ns))
        if tau_commanded is None or n == 0:
            return False
        limit_ns = max_age_s * 1e9
        diff = np.abs(self._overlay[:n] - tau_commanded)
        dist = np.max(diff, axis=1)
        best = int(np.argmin(dist))
        if dist[best] < self.closest_nm:
            self.closest_nm = float(dist[best])
            self.closest_joint = int(np.argmax(diff[best]))
        match = dist <= (self.tol_nm if tol_nm is None else tol_nm)
        if match.any():
            self.matched += 1
            is_old = t_ns - int(np.max(self._t_ns[:n][match])) > limit_ns
        else:
            is_old = t_ns - int(np.min(self._t_ns[:n])) > limit_ns
        if not is_old and match.any():
            self.applied_ns = t_ns
        return is_old

    def stall_reason(self, since_s: float, tol_nm: float) -> str:
        """Why no state has been on a recent overlay for ``since_s`` [s]: a robot that never echoed one since the
        reset (the closest it came named), or ours not reaching the stack."""
        if self.matched == 0:
            return (f"commanded_torque matched none of our overlays in {since_s:.1f} s since arming (closest "
                    f"{self.closest_nm:.4f} Nm off on A{self.closest_joint + 1}, tolerance {tol_nm:.4f}): the robot "
                    "does not echo the overlay; set [lbr] check_applied = false or applied_tolerance_nm")
        return (f"no state on a recent overlay of ours for {since_s:.1f} s: the robot runs on an old message (ours "
                "do not reach the stack)")


class FreezeWatch:
    """Measured positions bitwise unchanged for ``window_s`` of robot time while the sent overlay changed by more
    than ``torque_change_nm`` on some joint: a stream that is not the arm's."""

    def __init__(self, window_s: float, torque_change_nm: float = 1.0) -> None:
        self.window_ns = round(window_s * 1e9)
        self.torque_change_nm = torque_change_nm
        self._q: np.ndarray | None = None
        self._since_ns = 0
        self._tau_lo = np.zeros(0)  # the sent overlay's range since the positions froze (n,) [Nm], set at the first
        self._tau_hi = np.zeros(0)

    def reset(self) -> None:
        self._q = None

    def update(self, q: np.ndarray, t_ns: int, tau_sent: np.ndarray) -> str | None:
        """The reason the stream looks frozen, or None."""
        if self._q is None or not np.array_equal(q, self._q):
            self._q = np.array(q, float)
            self._since_ns = t_ns
            self._tau_lo = np.array(tau_sent, float)
            self._tau_hi = np.array(tau_sent, float)
            return None
        np.minimum(self._tau_lo, tau_sent, out=self._tau_lo)
        np.maximum(self._tau_hi, tau_sent, out=self._tau_hi)
        frozen_ns = t_ns - self._since_ns
        change = float(np.max(self._tau_hi - self._tau_lo))
        if frozen_ns >= self.window_ns and change > self.torque_change_nm:
            return (f"measured joint positions frozen for {frozen_ns / 1e6:.0f} ms under a {change:.1f} Nm overlay "
                    "change: not encoders (the stack's open_loop: true? set open_loop: false)")
        return None
