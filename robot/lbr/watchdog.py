"""The watchdog next to the stack: the release when the adapter's messages stop while the robot's states flow.

The stack re-applies the last message for as long as it runs
(lbr_torque_command_controller.cpp:42-55, rolling 218d723) and answers
every FRI cycle itself, so an adapter that dies without a word (killed, a
crash, the cell's host or network gone) leaves the robot on its last
message: a press goes on pressing, a hold has the stack's PID integrate
around the robot's spring (:mod:`robot.lbr.release`). ``lamps robot
--backend lbr --watchdog``, run on the robot PC beside the stack and the
bridge (so that a lost network between the cell and the robot PC does not
cut it off too), listens to the stack's state and command keys. Once it has
heard a command, a silence of ``watchdog_after_s`` while states keep
arriving makes it send the release, on each state for a few states and
then every ``RELEASE_REPEAT_S``, until a command that is not the release is
heard again (an adapter back, or a new one).

:class:`ReleaseWatch` is the rule as pure state (our monotonic clock [ns]);
:class:`Watchdog` puts it on the bridge's keys.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

from .params import LbrParams
from .release import RELEASE_BYTES, is_release

log = logging.getLogger(__name__)

#: The watchdog's service name (its liveliness token ``alive/lbr-watchdog``).
WATCHDOG_SERVICE = "lbr-watchdog"
#: States answered with the release at once when a silence begins, then one every this long [s].
RELEASE_BURST = 5
RELEASE_REPEAT_S = 0.1


class ReleaseWatch:
    """When to send the release: ``after_s`` [s] after the last command heard (not the release itself), on a state
    arriving; nothing before a first command."""

    def __init__(self, after_s: float) -> None:
        self.after_ns = round(after_s * 1e9)
        self.last_command_ns: int | None = None
        self.releasing = False
        self.counts: Counter[str] = Counter()
        self._sent_in_episode = 0
        self._last_sent_ns = 0

    def command(self, raw: bytes, t_ns: int) -> None:
        """A message on the stack's command key, heard at ``t_ns``."""
        if is_release(raw):
            return
        self.last_command_ns = t_ns
        if self.releasing:
            self.releasing = False
            self.counts["commands_resumed"] += 1
            log.warning("lbr watchdog: commands heard again: the release ends")

    def state(self, t_ns: int) -> bool:
        """A state heard at ``t_ns``: whether to send the release now."""
        if self.last_command_ns is None or t_ns - self.last_command_ns <= self.after_ns:
            return False
        if not self.releasing:
            self.releasing = True
            self._sent_in_episode = 0
            self.counts["release_episodes"] += 1
            log.error("lbr watchdog: no command for %.0f ms while the robot's states arrive: sending the release",
                      (t_ns - self.last_command_ns) / 1e6)
        if self._sent_in_episode < RELEASE_BURST or t_ns - self._last_sent_ns >= RELEASE_REPEAT_S * 1e9:
            self._sent_in_episode += 1
            self._last_sent_ns = t_ns
            self.counts["releases_sent"] += 1
            return True
        return False


class Watchdog:
    """:class:`ReleaseWatch` on the stack's keys of ``params`` through ``session`` (a Zenoh session reaching the
    bridge). :meth:`run` blocks until ``stop`` is set."""

    def __init__(self, params: LbrParams, session, after_s: float) -> None:
        self.watch = ReleaseWatch(after_s)
        self._lock = threading.Lock()
        self._send = False
        self._wake = threading.Event()
        t = params.topics
        self._pub = session.declare_publisher(t.key(t.torque_command))
        self._subs = [session.declare_subscriber(t.key(t.torque_command), self._on_command),
                      session.declare_subscriber(t.key(t.state), self._on_state)]

    def _on_command(self, sample) -> None:
        with self._lock:
            self.watch.command(sample.payload.to_bytes(), time.monotonic_ns())

    def _on_state(self, sample) -> None:
        with self._lock:
            if self.watch.state(time.monotonic_ns()):
                self._send = True
                self._wake.set()

    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            if self._wake.wait(0.1):
                self._wake.clear()
                with self._lock:
                    send, self._send = self._send, False
                if send:
                    self._pub.put(RELEASE_BYTES)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._pub.undeclare()
