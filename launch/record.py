"""Record every key of a cell into an MCAP file that opens in Foxglove.

One subscription on ``<prefix>/**``; the Zenoh thread only appends the raw
sample to a queue, a writer thread decodes and writes. Each key is a channel
(topic = the key) with JSON messages (field names as in
``interfaces/messages.py``; ``bytes`` as base64) and a JSON schema with every
property (:mod:`launch.schemas`: the open-source Foxglove / Lichtblick
decoders drop a channel whose schema has none), except camera frames,
which are written as ``foxglove.CompressedImage`` (JPEG) so Foxglove shows
them, with their pose and intrinsics on ``<key>/info``. ``log_time`` is the
wall clock at receipt [ns]; the message's own stamps stay in the message.
The controller trace (packed 1 kHz batches, kept whole) is also written every
:data:`~launch.record_json.TRACE_PLOT_EVERY`-th tick as one row per message on ``<key>/plot``,
back-dated from the batch's receipt by the controller clock, so a plot
panel draws its columns over time. The 3D scene and the image overlays
(:mod:`launch.scene`: transforms of the arm's links, the pad, the board and
the cameras; the arm's shapes; the board and its stains; camera
calibrations and stain outlines on the images) are Foxglove's own typed
messages (protobuf, schemas from ``foxglove-sdk``).

A recorder started again in a run folder (a restart after a crash, or
``docker compose restart``) continues the same recording: it carries every
complete message of its predecessor's file (``.partial`` or finished) over
into its own before it records anything new, writes a marker on
:data:`RESUMED_TOPIC`, and replaces the old file only once the carried copy
is on the disk, so nothing recorded before is lost.

The file is written as ``recording.mcap.partial`` and renamed when finished,
so a half-written recording is never mistaken for a whole one. It is written
in small chunks (:data:`CHUNK_BYTES`) and flushed to the disk every
:data:`FLUSH_S`, so after a crash (SIGKILL, power) all but the last second
or so is on the disk in complete chunks: :func:`recover_recording` reads
them back (a tolerant stream read up to the first damaged record) into a
whole MCAP file, which ``lamps report`` does by itself for a run folder that
has only the partial file.
"""

from __future__ import annotations

import base64
import logging
import os
import threading
import time
from collections import Counter, deque
from pathlib import Path

import msgspec
import numpy as np

from interfaces.codec import Decoder
from interfaces.errors import MessageDecodeError
from interfaces.keys import Keys

from .record_budget import SHUT, THIN_FROM, Account, Budget
from .record_json import message_type_of

# the file itself; re-exported here, where the recording's readers and the tests have always found them
from .record_sink import CHUNK_BYTES, FLUSH_S, RECORDER_ACCOUNT, McapSink, iter_records, recover_recording

__all__ = ["CHUNK_BYTES", "FLUSH_S", "McapSink", "iter_records", "recover_recording", "Recorder", "RECORDING",
           "RESUMED_TOPIC", "STATUS_TOPIC", "SELF_REPORTS_TOPIC", "budget_from_env", "read_recording",
           "trace_array"]

log = logging.getLogger(__name__)

RECORDING = "recording.mcap"
#: The topic (outside the cell's keys) where a recorder that carried an earlier recording over says so.
RESUMED_TOPIC = "recorder/resumed"
_RESUMED_SCHEMA = {"type": "object", "title": "lamps.RecorderResumed",
                   "properties": {"carried_messages": {"type": "integer"}, "earlier_file": {"type": "string"},
                                  "earlier_finished": {"type": "boolean"}, "last_earlier_ns": {"type": "integer"}}}
#: The recorder's account of every key, once a second and when it closes (``final``): what it received,
#: recorded and dropped and why, and what each key takes of its share of the disk budget.
STATUS_TOPIC = "recorder/status"
#: At its close: which messages of the services' own statuses and truth it wrote from what it kept whatever its
#: budget, because the recording of their key had stopped or thinned before them.
SELF_REPORTS_TOPIC = "recorder/self_reports"
#: The recorder's status is written this often [s].
STATUS_PERIOD_S = 1.0
#: For each key of :data:`~launch.record_budget.SELF_REPORTS`, the newest message of each of the last this many
#: seconds is kept (a controller stopped mid-wipe lifts the pad for up to 6 s before it exits: its status from
#: before the cell began stopping is among them).
SELF_REPORT_SECONDS = 16
#: At most this many rejected samples per key are described on ``<key>/rejected`` (their size and the error,
#: never their bytes), and as many of every other key together; the rest are only counted.
REJECTED_NOTES_PER_KEY = 100
#: The recording's disk budget [bytes] by default (``LAMPS_RECORD_MAX_MB`` sets it in MiB).
DEFAULT_BUDGET_BYTES = 4 * 1024**3
_OTHER_KEYS = "keys of no message type"
_REJECTED_SCHEMA = {"type": "object", "title": "lamps.Rejected",
                    "properties": {"error": {"type": "string"}, "bytes": {"type": "integer"},
                                   "rejected_so_far": {"type": "integer"}}}
_BUDGET_SCHEMA = {"type": "object", "title": "lamps.RecorderBudget",
                  "properties": {"budget_bytes": {"type": "integer"}, "message": {"type": "string"},
                                 "key": {"type": "string"}, "state": {"type": "string"},
                                 "share_bytes": {"type": "integer"}}}
_ACCOUNT_SCHEMA = {"type": "object", "properties": {
    "key": {"type": "string"}, "state": {"type": "string"}, "share_bytes": {"type": "integer"},
    "used_bytes": {"type": "integer"}, "received": {"type": "integer"}, "recorded": {"type": "integer"},
    "dropped": {"type": "object", "additionalProperties": {"type": "integer"}}}}
_STATUS_SCHEMA = {"type": "object", "title": "lamps.RecorderStatus", "properties": {
    "final": {"type": "boolean"}, "budget_bytes": {"type": "integer"}, "file_bytes": {"type": "integer"},
    "over_budget": {"type": "boolean"}, "queued_bytes": {"type": "integer"},
    "counters": {"type": "object", "additionalProperties": {"type": "integer"}},
    "keys": {"type": "array", "items": _ACCOUNT_SCHEMA}}}
_SELF_REPORTS_SCHEMA = {"type": "object", "title": "lamps.RecorderSelfReports", "properties": {
    "messages": {"type": "array", "items": {"type": "object", "properties": {
        "key": {"type": "string"}, "log_time_ns": {"type": "integer"}}}}}}


def budget_from_env() -> int:
    """The disk budget [bytes] from ``LAMPS_RECORD_MAX_MB`` (MiB, > 0), or :data:`DEFAULT_BUDGET_BYTES`."""
    raw = os.environ.get("LAMPS_RECORD_MAX_MB", "").strip()
    if not raw:
        return DEFAULT_BUDGET_BYTES
    try:
        mb = float(raw)
    except ValueError:
        mb = -1.0
    if not mb > 0:
        raise ValueError(f"LAMPS_RECORD_MAX_MB must be a positive number of MiB, got {raw!r}")
    return int(mb * 1024**2)


def _mib(n_bytes: int) -> str:
    return f"{n_bytes / 1024**2:.3g} MiB"


class Recorder:
    """Subscribes ``<prefix>/**`` on ``session`` and writes ``out_dir/recording.mcap`` until :meth:`close`.

    ``keys``: the cell's, or a sequence of cells' (a site's recording, ``lamps record --cells``: every cell's keys
    under their own prefixes, each cell's scene in its own frame tree, :func:`launch.scene.cell_frames`).

    It records what the cell's receivers accept, within each key's share of ``budget_bytes``
    (:mod:`launch.record_budget`): a sample of a key of no message type, or over its type's size bound, is
    counted (``unknown_key``, ``undecodable``) and dropped in Zenoh's thread, before its bytes are copied; one
    that does not decode is counted by the writer. Each is described, its size and the error, on
    ``<key>/rejected``, for its key's first :data:`REJECTED_NOTES_PER_KEY`. A sample past its key's part of the
    queue, or of an image past its share, or of a thinned key within a second of the last kept, is counted
    (``dropped_queue_full``, ``dropped_over_share``, ``dropped_thinned``) and dropped there too. A key that
    reaches :data:`~launch.record_budget.THIN_FROM` of its share or all of it says so once on
    ``recorder/budget``; past the whole budget nothing more is recorded (``dropped_over_budget``), said there
    too, and the file is finished as usual. Every second, and when it closes, the recorder writes its account
    of every key on :data:`STATUS_TOPIC`; at its close it also writes the services' newest statuses and truth
    it kept that the recording of their key had missed (:data:`SELF_REPORTS_TOPIC` names them).
    """

    def __init__(self, session, keys: Keys | list[Keys], out_dir: Path, max_queue: int = 200_000,
                 budget_bytes: int = DEFAULT_BUDGET_BYTES, clock=time.time_ns) -> None:
        from .scene import cells_of, scenes_of

        self.cells = cells_of(keys)
        self.clock = clock  # log_time of a sample [ns]: the wall clock, or the network-free cell's robot clock
        self.budget_bytes = budget_bytes
        self.budget = Budget(self.cells, budget_bytes)
        self.over_budget = False
        self.keys = self.cells[0]
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.partial = self.out_dir / (RECORDING + ".partial")
        self.counters: Counter[str] = Counter()
        self.sink = self._open_sink()
        for acc in self.budget.accounts.values():  # what an earlier recorder of the folder recorded counts too
            state = acc.charge(self.sink.used(acc.name))
            if state is not None:
                self._say_share(acc, state, self.clock())
        self.max_queue = max_queue
        self._queue: deque = deque()  # (key, payload or None, t_ns, account or None, bytes queued or a note)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._decoders: dict[str, tuple] = {}  # key -> (decoder, its cell's scene, its prefix's length)
        self._rejected: Counter[str] = Counter()
        self._newest: dict[str, deque] = {}  # self-report key -> (second, t_ns, payload) of its last seconds
        self._last_recorded: dict[str, int] = {}
        self._next_status = time.monotonic() + STATUS_PERIOD_S
        self.scenes = scenes_of(self.cells)
        self.scene = self.scenes[self.keys.prefix]
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()
        self._subs = [session.declare_subscriber(f"{k.prefix}/**", self._on_sample) for k in self.cells]

    def _open_sink(self) -> McapSink:
        """The sink at ``recording.mcap.partial``, holding first whatever an earlier recorder of this folder
        recorded (its ``.partial`` if it died, else its finished file), charged to its keys' shares. The earlier
        file is replaced only once the copy is on the disk."""
        final = self.out_dir / RECORDING
        earlier = self.partial if self.partial.is_file() else final if final.is_file() else None
        if earlier is None:
            return McapSink(self.partial)
        fresh = self.partial.with_name(self.partial.name + ".new")
        sink = McapSink(fresh)
        n, last_ns = sink.carry_over(earlier, self.budget.account_of_topic)
        sink.write_json(RESUMED_TOPIC, "lamps.RecorderResumed",
                        {"carried_messages": n, "earlier_file": earlier.name, "earlier_finished": earlier == final,
                         "last_earlier_ns": last_ns}, self.clock(), _RESUMED_SCHEMA)
        sink.flush()
        os.replace(fresh, self.partial)  # the open file follows the rename
        sink.path = self.partial
        if earlier == final:
            final.unlink()
        self.counters["carried_over"] = n
        log.warning("continuing the recording of %s: %d earlier messages carried over from %s", self.out_dir, n,
                    earlier.name)
        return sink

    # -- Zenoh's thread: checks, then queues; never waits, never copies what it drops ---------------------------
    def _on_sample(self, sample) -> None:
        key, t_ns, payload = str(sample.key_expr), self.clock(), sample.payload
        local = hasattr(payload, "decoded")  # the in-process bus's payload: its message, decoded once
        n = 0 if local else len(payload)
        acc = self.budget.account_of(key)
        if acc is None:
            self._reject(key, None, n, t_ns, "unknown_key", "no message type for this key")
            return
        if acc.self_report:
            self._keep_newest(key, payload, t_ns)
        if not local:
            try:
                self._decoder(key)[0].check_size(n)
            except MessageDecodeError as exc:
                self.budget.refused(acc, "oversized")
                self._reject(key, acc, n, t_ns, "undecodable", str(exc))
                return
        why = self.budget.admit(acc, n, t_ns, room=len(self._queue) < self.max_queue)
        if why is not None:
            self.counters[f"dropped_{why}"] += 1
            return
        self._queue.append((key, payload if local else payload.to_bytes(), t_ns, acc, n))
        if not self._wake.is_set():  # set once until the writer wakes (a set Event costs a lock and a notify)
            self._wake.set()

    def _reject(self, key: str, acc: Account | None, n_bytes: int, t_ns: int, counter: str, error: str,
                queue: bool = True) -> None:
        """Count a rejected sample; describe it on ``<key>/rejected`` while its key has notes left."""
        self.counters[counter] += 1
        notes = key if acc is not None else _OTHER_KEYS
        self._rejected[notes] += 1
        if self._rejected[notes] > REJECTED_NOTES_PER_KEY:
            return
        note = {"error": error[:200], "bytes": n_bytes, "rejected_so_far": self._rejected[notes]}
        if not queue:
            self.sink.write_json(key + "/rejected", "lamps.Rejected", note, t_ns, _REJECTED_SCHEMA)
            return
        self._queue.append((key, None, t_ns, None, note))
        self._wake.set()

    def _keep_newest(self, key: str, payload, t_ns: int) -> None:
        """The newest message of each second of ``key``'s last :data:`SELF_REPORT_SECONDS` (its payload: not
        copied)."""
        ring = self._newest.get(key)
        if ring is None:
            ring = self._newest[key] = deque(maxlen=SELF_REPORT_SECONDS)
        second = t_ns // 10**9
        if ring and ring[-1][0] == second:
            ring[-1] = (second, t_ns, payload)
        else:
            ring.append((second, t_ns, payload))

    def _decoder(self, key: str) -> tuple:
        """(decoder, scene, prefix length) of ``key``, a key of the cell's (:meth:`Budget.account_of`)."""
        entry = self._decoders.get(key)
        if entry is None:
            from .scene import cell_of_key

            cell = cell_of_key(self.cells, key)
            t = message_type_of(cell, key) if cell is not None else None
            if cell is None or t is None:
                raise KeyError(f"{key} is no message key of the cells recorded")
            entry = self._decoders[key] = (Decoder(t), self.scenes[cell.prefix], len(cell.prefix) + 1)
        return entry

    # -- the writer's thread ---------------------------------------------------------------------------------
    def _drain(self) -> None:
        while self._queue:
            key, data, t_ns, acc, extra = self._queue.popleft()
            if acc is not None:
                self.budget.taken(acc, extra)
            if self.over_budget or self._check_budget(t_ns):
                self.counters["dropped_over_budget"] += 1
                self.budget.refused(acc, "over_budget")
            elif acc is None:
                self.sink.write_json(key + "/rejected", "lamps.Rejected", extra, t_ns, _REJECTED_SCHEMA)
            elif acc.state == SHUT:  # its share was used up while it waited
                self.counters["dropped_over_share"] += 1
                self.budget.refused(acc, "over_share")
            else:
                msg = self._decoded(key, data, t_ns, acc)
                data = None  # the payload goes before its message is written: a 12 MB frame is one copy less
                if msg is not None:
                    self._write(key, msg, t_ns, acc)

    def _decoded(self, key: str, data, t_ns: int, acc: Account):
        """The message of a queued sample of ``key``, or None when it does not decode (counted, described)."""
        dec = self._decoder(key)[0]
        try:
            return dec(data) if isinstance(data, bytes) else data.decoded(dec)
        except MessageDecodeError as exc:
            self.budget.refused(acc, "undecodable")
            self._reject(key, acc, len(data) if isinstance(data, bytes) else 0, t_ns, "undecodable", str(exc),
                         queue=False)
            return None

    def _write(self, key: str, msg, t_ns: int, acc: Account) -> None:
        """Write one message of ``key``, its scene messages too, all charged to its account."""
        _, scene, after_prefix = self._decoder(key)
        self.sink.account = acc.name
        try:
            self.sink.write(key, msg, t_ns)
            for topic, scene_msg in scene.on_message(key, msg, t_ns):
                self.sink.write_typed(topic, scene_msg, t_ns)
        finally:
            self.sink.account = RECORDER_ACCOUNT
        acc.recorded += 1
        self.counters[key[after_prefix:]] += 1
        self._last_recorded[key] = t_ns
        state = acc.charge(self.sink.used(acc.name))
        if state is not None:
            self._say_share(acc, state, t_ns)

    def _say_share(self, acc: Account, state: str, t_ns: int) -> None:
        """One ``recorder/budget`` message (and a warning) when ``acc`` is thinned or shut."""
        share = f"{_mib(acc.share_bytes)} of the {_mib(self.budget_bytes)} disk budget (LAMPS_RECORD_MAX_MB)"
        message = (f"{acc.name} used its share, {share}: no more of it is recorded" if state == SHUT else
                   f"{acc.name} used {THIN_FROM:.0%} of its share, {share}: one message a second from now on")
        log.warning("%s", message)
        self.sink.write_json("recorder/budget", "lamps.RecorderBudget",
                             {"budget_bytes": self.budget_bytes, "key": acc.name, "state": state,
                              "share_bytes": acc.share_bytes, "message": message}, t_ns, _BUDGET_SCHEMA)

    def _check_budget(self, t_ns: int) -> bool:
        """True (and said once) when the file has reached its disk budget."""
        if self.sink.bytes_written() < self.budget_bytes:
            return False
        self.over_budget = True
        message = (f"the recording reached its disk budget of {_mib(self.budget_bytes)} (LAMPS_RECORD_MAX_MB): "
                   "nothing more is recorded in this run")
        log.error("%s", message)
        self.sink.write_json("recorder/budget", "lamps.RecorderBudget",
                             {"budget_bytes": self.budget_bytes, "message": message}, t_ns, _BUDGET_SCHEMA)
        return True

    def status(self, final: bool = False) -> dict:
        """The recorder's account (what :data:`STATUS_TOPIC` carries): its counters and every key's that has seen
        a sample."""
        accounts = list(self.budget.accounts.values())
        return {"final": final, "budget_bytes": self.budget_bytes, "file_bytes": self.sink.bytes_written(),
                "over_budget": self.over_budget, "counters": dict(self.counters),
                "queued_bytes": sum(a.queued_in - a.queued_out for a in accounts),
                "keys": [a.summary() for a in accounts if a.received or a.used_bytes]}

    def _write_status(self, final: bool = False) -> None:
        self.sink.write_json(STATUS_TOPIC, "lamps.RecorderStatus", self.status(final), self.clock(), _STATUS_SCHEMA)

    def _write_self_reports(self) -> None:
        """The newest statuses and truth kept (:meth:`_keep_newest`) that are newer than their key's last recorded
        message, on their keys; and on :data:`SELF_REPORTS_TOPIC`, which they are. Whatever the budget: at most
        :data:`SELF_REPORT_SECONDS` messages of a few keys."""
        added = []
        for key, ring in self._newest.items():
            dec = self._decoder(key)[0]
            for _, t_ns, payload in ring:
                if t_ns <= self._last_recorded.get(key, -1):
                    continue
                try:
                    msg = payload.decoded(dec) if hasattr(payload, "decoded") else dec(payload.to_bytes())
                except MessageDecodeError:
                    continue
                acc = self.budget.account_of(key)
                assert acc is not None  # a key kept by _keep_newest had its account then, and keeps it
                self.sink.account = acc.name
                self.sink.write(key, msg, t_ns)
                added.append({"key": key, "log_time_ns": t_ns})
        self.sink.account = RECORDER_ACCOUNT
        if added:
            self.sink.write_json(SELF_REPORTS_TOPIC, "lamps.RecorderSelfReports", {"messages": added}, self.clock(),
                                 _SELF_REPORTS_SCHEMA)
            self.counters["self_reports_written_at_close"] = len(added)

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(0.1)
            self._wake.clear()
            self._drain()
            if time.monotonic() >= self._next_status and not self.over_budget:
                self._next_status = time.monotonic() + STATUS_PERIOD_S
                self._write_status()
            self.sink.flush(FLUSH_S)

    def close(self) -> Path:
        """Stop, write what is queued, the services' last statuses the recording missed and the recorder's final
        account, finish the file; returns the recording's final path."""
        for sub in self._subs:
            sub.undeclare()
        self._stop.set()
        self._wake.set()
        self._thread.join(60.0)
        self._drain()
        self._write_self_reports()
        self._write_status(final=True)
        self.sink.finish()
        final = self.out_dir / RECORDING
        os.replace(self.partial, final)
        return final


def read_recording(path: Path) -> dict[str, list[tuple[int, dict]]]:
    """Every JSON message of a recording by topic: [(log_time_ns, JSON object)], in log-time order (the scene's
    typed protobuf channels are left out)."""
    from mcap.reader import make_reader

    loads = msgspec.json.Decoder().decode  # the same objects as json.loads gives, faster
    out: dict[str, list[tuple[int, dict]]] = {}
    with open(path, "rb") as f:
        # in file order, then each topic sorted by log time (stable: ties keep the file's order, as the reader's
        # log-time merge keeps them): the reader's merge compares every message in Python, a third of the read
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if channel.message_encoding == "json":
                out.setdefault(channel.topic, []).append((message.log_time, loads(message.data)))
    for messages in out.values():
        messages.sort(key=_log_time)
    return out


def _log_time(entry: tuple[int, dict]) -> int:
    return entry[0]


def trace_array(batches: list[dict]) -> tuple[list[str], np.ndarray]:
    """Recorded ``controller/trace`` batches -> (columns, (n, c) rows in tick order; gaps left out)."""
    if not batches:
        return [], np.zeros((0, 0))
    cols = batches[0]["columns"]
    rows = sorted(((b["first_tick"], np.frombuffer(base64.b64decode(b["data"]), "<f8").reshape(-1, len(cols)))
                   for b in batches if b["columns"] == cols), key=lambda r: r[0])
    return cols, np.vstack([r for _, r in rows]) if rows else np.zeros((0, len(cols)))
