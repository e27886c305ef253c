"""The stack's torque-command subscription: ``LBRTorqueCommand`` samples as its controller gets them.

The lbr peer's (:mod:`sim.lbr_stack.peer`) inbox for ``<namespace>/command/torque``: valid messages kept in order
(lock-step) or the newest taken (real time); undecodable, wrong-length or non-finite ones dropped and counted by
reason (the bridge would not deliver them as ``LBRTorqueCommand``), except the release (robot/lbr/release.py:
``joint_position`` NaN, zero torque), which reaches the stack as it would the real one (counted ``releases_received``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque

import numpy as np
import zenoh

from robot.lbr.msgs import N_JOINTS, LbrWireError, decode_torque_command
from robot.lbr.release import RELEASE_JOINT_POSITION, RELEASE_TORQUE, is_release

log = logging.getLogger(__name__)

#: A CDR LBRTorqueCommand: 4-byte encapsulation header, then two float64[7] (fixed arrays, no length field).
TORQUE_COMMAND_BYTES = 4 + 2 * N_JOINTS * 8
_LOG_PERIOD_S = 5.0


def drop_reason(raw: bytes, exc: LbrWireError) -> str:
    """Why a torque command was dropped: ``non_finite``, ``wrong_length``, ``not_cdr`` or ``malformed_cdr``."""
    text = str(exc)
    if "NaN" in text:
        return "non_finite"
    if "must hold" in text:
        return "wrong_length"
    if len(raw) < 4 or raw[0] != 0 or raw[1] > 0x0B:  # no CDR encapsulation header
        return "not_cdr"
    return "wrong_length" if len(raw) != TORQUE_COMMAND_BYTES else "malformed_cdr"  # fixed arrays: size = length


class CommandBox:
    """``LBRTorqueCommand`` samples of one key; bad ones counted by reason, dropped.

    Lock-step waits for the oldest with :meth:`get` (decoded in Zenoh's thread, handed over under a lock).
    Real time (``channel=True``) takes the newest with :meth:`newest`: Zenoh queues the raw samples in a ring
    of ``maxlen`` without Python, and the loop decodes them itself. A Python callback needs the GIL, which the
    simulator's step holds (PyBullet does not release it): with a busy loop a command could wait up to
    the interpreter's switch interval (5 ms) per sample, and they piled up (a 100 ms pile-up tripped the
    watchdog in a real-time run).
    """

    def __init__(self, session, key: str, maxlen: int = 64, channel: bool = False) -> None:
        self.key = key
        self.received = 0
        self.overflowed = 0
        self.releases = 0
        self.dropped: Counter[str] = Counter()
        self._queue: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=maxlen)
        self._ready = threading.Condition()
        self._last_log = -float("inf")
        self._channel = channel
        if channel:
            self._sub = session.declare_subscriber(key, zenoh.handlers.RingChannel(maxlen))
        else:
            self._sub = session.declare_subscriber(key, self._on_sample)

    def _decode(self, raw: bytes) -> tuple[np.ndarray, np.ndarray] | None:
        """The command in ``raw``, or None (counted by reason, logged at most every few seconds)."""
        if is_release(raw):
            with self._ready:
                self.releases += 1
            return RELEASE_JOINT_POSITION.copy(), RELEASE_TORQUE.copy()
        try:
            return decode_torque_command(raw)
        except LbrWireError as exc:
            with self._ready:
                self.received += 1
                self.dropped[drop_reason(raw, exc)] += 1
            now = time.monotonic()
            if now - self._last_log >= _LOG_PERIOD_S:
                self._last_log = now
                log.warning("dropped a torque command on %s (%d so far): %s", self.key,
                            sum(self.dropped.values()), exc)
            return None

    def _on_sample(self, sample) -> None:
        command = self._decode(sample.payload.to_bytes())
        if command is None:
            return
        with self._ready:
            self.received += 1
            if len(self._queue) == self._queue.maxlen:
                self.overflowed += 1
            self._queue.append(command)
            self._ready.notify()

    def get(self, timeout_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The oldest valid command not yet taken, waiting up to ``timeout_s``; None on timeout (lock-step)."""
        if self._channel:
            raise RuntimeError("CommandBox.get needs the callback box (channel=False)")
        with self._ready:
            if not self._queue and not self._ready.wait_for(lambda: bool(self._queue), timeout_s):
                return None
            return self._queue.popleft()

    def newest(self) -> tuple[tuple[np.ndarray, np.ndarray] | None, int]:
        """(the newest valid command or None, how many older valid ones it superseded); never blocks."""
        if self._channel:
            newest, valid = None, 0
            while (sample := self._sub.try_recv()) is not None:
                command = self._decode(sample.payload.to_bytes())
                if command is not None:
                    newest, valid = command, valid + 1
            with self._ready:
                self.received += valid
            return newest, max(valid - 1, 0)
        with self._ready:
            if not self._queue:
                return None, 0
            command, superseded = self._queue[-1], len(self._queue) - 1
            self._queue.clear()
            return command, superseded

    def counters(self) -> dict[str, int]:
        with self._ready:
            out = {"commands_received": self.received, "commands_overflowed": self.overflowed,
                   "releases_received": self.releases}
            out.update({f"commands_dropped_{reason}": n for reason, n in self.dropped.items()})
        return out

    def close(self) -> None:
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None
