"""The recorder's budget: each key of a cell has its own share of the disk and of the queue, so one role's flood
cannot starve the others.

Perception's identity once put 12 MB debug frames until the recording's disk budget ran out: the recording
stopped for every key, the report said "incomplete, 69 %" of a clean board, and the recorder's memory grew
from 235 to 520 MB (payloads were queued before any check). The rule now, with ``B`` the disk budget
(``LAMPS_RECORD_MAX_MB``, default 4096 MiB):

* **Before a sample is queued** (in Zenoh's thread, its bytes not yet copied) it is checked: its key must be
  one of the cell's message keys (each written by the roles :func:`interfaces.access.writers` names; the
  access list has already refused any other role's put on it, Zenoh samples name no sender of their own), its
  size within its type's bound (:meth:`interfaces.codec.Decoder.check_size`), and its key's part of the queue
  (:attr:`Account.queue_bytes`: its share of :data:`QUEUE_BYTES`, at least one message of its type's largest)
  not full. Otherwise it is counted and dropped. So the queue holds at most :meth:`Budget.queue_bound` bytes.
* **On the disk** each key takes at most its share of ``B`` (:data:`SHARES`), counted as what its messages
  add to the file (its part of each compressed chunk, :meth:`launch.record_sink.McapSink.used`). Images
  (camera frames, perception's debug frames) are recorded until their share is used, then no more. Every
  other key (the states, the commands, the trace, the statuses, the truth, the stains, the e-stops, the arm
  requests) is always recorded: at full rate up to :data:`THIN_FROM` of its share, then thinned to one
  message a second (:data:`THIN_PERIOD_S`) for the rest of it (at the default budget, hours of it).
* The shares add up to 95 %: the rest is the file's index and the recorder's own messages (its status once a
  second, at most a hundred notes per key), bounded by their rate and count. The file as a whole still
  stops at ``B``.

With several cells in one recording (a site), each cell's keys share ``B / n_cells``.
"""

from __future__ import annotations

import re
import threading
from collections import Counter
from dataclasses import dataclass, field

from interfaces.keys import Keys
from interfaces.messages import MAX_PAYLOAD_BYTES

from .record_json import message_type_of

#: Each key's share of the disk budget (a fraction of it) and whether it is always recorded (thinned past
#: :data:`THIN_FROM` of its share) or, an image, stopped at its share. ``camera/*/frame``: every camera together.
SHARES: dict[str, tuple[float, bool]] = {
    "robot/state": (0.32, True), "robot/command": (0.10, True), "controller/trace": (0.22, True),
    "controller/status": (0.03, True), "sim/truth": (0.03, True), "sim/status": (0.01, True),
    "robot/status": (0.01, True), "perception/status": (0.01, True), "controller/estop": (0.005, True),
    "controller/estop/release": (0.005, True), "robot/arm": (0.005, True), "perception/stains": (0.05, True),
    "robot/introduction": (0.005, True), "controller/introduction": (0.005, True),
    "camera/*/frame": (0.10, False), "perception/debug": (0.045, False),
}
#: The keys whose newest messages the recorder keeps whatever its budget, to write at its close what the
#: services last said of themselves (their status, the sim's truth) when the recording of them had stopped.
SELF_REPORTS = ("controller/status", "sim/status", "robot/status", "perception/status", "sim/truth")
#: An always-recorded key is thinned past this fraction of its share.
THIN_FROM = 0.9
#: A thinned key keeps one message this often [s] (by receipt time).
THIN_PERIOD_S = 1.0
#: The queue's bytes shared out as the disk is [bytes] (a key's part is at least one message of its type's largest).
QUEUE_BYTES = 32 * 1024**2
#: At most this many distinct keys are recorded (a camera name is part of its key); further keys are refused.
MAX_KEYS = 256
#: An account's states: recording everything, thinned, no more.
FULL, THIN, SHUT = "full", "thinned", "shut"
_CAMERA = re.compile(r"^camera/[^/]+/frame$")


@dataclass
class Account:
    """One key's (or every camera's) part of the budget, and what became of its samples.

    name : the key expression (``lamps/iiwa/robot/state``, ``lamps/iiwa/camera/*/frame``); share_bytes,
    queue_bytes : its part of the disk and of the queue [bytes]; max_bytes : its type's payload bound [bytes];
    always : thinned past :data:`THIN_FROM` of its share rather than stopped at it.
    """

    name: str
    share_bytes: int
    queue_bytes: int
    max_bytes: int
    always: bool
    self_report: bool = False
    state: str = FULL
    received: int = 0
    recorded: int = 0
    used_bytes: int = 0
    dropped: Counter = field(default_factory=Counter)
    queued_in: int = 0  # bytes ever queued (Zenoh's thread) and taken out (the writer): queued = in - out
    queued_out: int = 0
    last_kept_ns: int = -(2**62)

    def charge(self, used_bytes: int) -> str | None:
        """Its file bytes so far [bytes] -> the new state when that changes (None if not)."""
        self.used_bytes = used_bytes
        state = self.state
        if used_bytes >= self.share_bytes:
            state = SHUT
        elif self.always and used_bytes >= THIN_FROM * self.share_bytes:
            state = THIN
        if state == self.state:
            return None
        self.state = state
        return state

    def summary(self) -> dict:
        """What the recorder says of it on ``recorder/status``."""
        return {"key": self.name, "state": self.state, "share_bytes": self.share_bytes,
                "used_bytes": self.used_bytes, "received": self.received, "recorded": self.recorded,
                "dropped": dict(self.dropped)}


class Budget:
    """The accounts of a recording's keys; :meth:`admit` in Zenoh's thread, :meth:`taken` in the writer's."""

    def __init__(self, cells: list[Keys], budget_bytes: int, queue_bytes: int = QUEUE_BYTES) -> None:
        if budget_bytes <= 0:
            raise ValueError(f"the disk budget must be positive, got {budget_bytes} bytes")
        self.cells = cells
        self.budget_bytes = budget_bytes
        self.accounts: dict[str, Account] = {}
        for cell in cells:
            for suffix, (fraction, always) in SHARES.items():
                t = message_type_of(cell, f"{cell.prefix}/{suffix.replace('*', 'x')}")
                if t is None:
                    raise ValueError(f"the recorder's share {suffix!r} is no message key of the cell")
                name = f"{cell.prefix}/{suffix}"
                self.accounts[name] = Account(
                    name, int(budget_bytes * fraction / len(cells)), max(int(queue_bytes * fraction / len(cells)),
                                                                         MAX_PAYLOAD_BYTES[t]),
                    MAX_PAYLOAD_BYTES[t], always, suffix in SELF_REPORTS)
        self._by_key: dict[str, Account | None] = {}
        self._lock = threading.Lock()

    def account_of(self, key: str) -> Account | None:
        """The account of the concrete ``key``; None for a key that is no message key of the cell (or one key
        too many: :data:`MAX_KEYS`)."""
        acc = self._by_key.get(key)
        if acc is not None or len(self._by_key) >= MAX_KEYS:
            return acc
        acc = self.accounts.get(self._name_of(key) or "")
        if acc is not None:  # only the cell's keys are remembered: a flood of other keys grows nothing
            self._by_key[key] = acc
        return acc

    def _name_of(self, key: str) -> str | None:
        cell = next((c for c in self.cells if key.startswith(c.prefix + "/")), None)
        if cell is None:
            return None
        suffix = key[len(cell.prefix) + 1:]
        name = f"{cell.prefix}/camera/*/frame" if _CAMERA.match(suffix) else key
        return name if message_type_of(cell, key) is not None else None

    def account_of_topic(self, topic: str) -> str | None:
        """The account a recorded ``topic`` is charged to (a key's, its ``/info``, ``/plot`` or ``/rejected``
        topic's too); None for another (the scene's, the recorder's)."""
        for end in ("", "/info", "/plot", "/rejected"):
            if end and not topic.endswith(end):
                continue
            acc = self.account_of(topic[:len(topic) - len(end)])
            if acc is not None:
                return acc.name
        return None

    def admit(self, acc: Account, n_bytes: int, t_ns: int, room: bool = True) -> str | None:
        """Whether a sample of ``n_bytes`` received at ``t_ns`` [ns] may be queued: None, or why not (``over_share``,
        ``thinned``, ``queue_full``; ``room`` False: the queue holds as many samples as it may); an admitted one is
        counted as queued."""
        with self._lock:
            acc.received += 1
            why = None
            if acc.state == SHUT:
                why = "over_share"
            elif acc.state == THIN and t_ns - acc.last_kept_ns < THIN_PERIOD_S * 1e9:
                why = "thinned"
            elif not room or acc.queued_in - acc.queued_out + n_bytes > acc.queue_bytes:
                why = "queue_full"
            if why is not None:
                acc.dropped[why] += 1
                return why
            acc.queued_in += n_bytes
            acc.last_kept_ns = t_ns
            return None

    def refused(self, acc: Account | None, why: str) -> None:
        """A sample of ``acc`` counted and dropped for ``why``: ``oversized`` (before it was queued: counted as
        received too), ``undecodable``, ``over_share`` or ``over_budget`` (after)."""
        if acc is not None:
            with self._lock:
                acc.received += why == "oversized"
                acc.dropped[why] += 1

    def taken(self, acc: Account, n_bytes: int) -> None:
        """The writer took a queued sample of ``n_bytes`` out of the queue."""
        with self._lock:
            acc.queued_out += n_bytes

    def queue_bound(self) -> int:
        """The most the queue may hold [bytes]: every account's part together."""
        return sum(a.queue_bytes for a in self.accounts.values())
