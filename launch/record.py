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
import json
import logging
import os
import struct
import threading
import time
import zlib
from collections import Counter, deque
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import zstandard as zstd
from mcap.writer import Writer

from interfaces.codec import Decoder
from interfaces.errors import MessageDecodeError
from interfaces.keys import Keys
from interfaces.messages import Message

from .record_json import json_records, message_type_of

log = logging.getLogger(__name__)

RECORDING = "recording.mcap"
#: The topic (outside the cell's keys) where a recorder that carried an earlier recording over says so.
RESUMED_TOPIC = "recorder/resumed"
_RESUMED_SCHEMA = {"type": "object", "title": "lamps.RecorderResumed",
                   "properties": {"carried_messages": {"type": "integer"}, "earlier_file": {"type": "string"},
                                  "earlier_finished": {"type": "boolean"}, "last_earlier_ns": {"type": "integer"}}}
#: MCAP chunk size [bytes]: small, so a crash loses little (a chunk is on the disk only once complete).
CHUNK_BYTES = 256 * 1024
#: The recording is pushed to the disk this often [s].
FLUSH_S = 1.0


class _Counted:
    """A binary stream that knows its position without asking the OS: :meth:`tell` is read once per message (the
    disk budget), a system call each time on a file."""

    def __init__(self, f) -> None:
        self._f = f
        self._pos = f.tell()

    def write(self, data) -> int:
        n = self._f.write(data)
        self._pos += len(data)
        return n

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        self._f.flush()

    def fileno(self) -> int:
        return self._f.fileno()

    def close(self) -> None:
        self._f.close()


class McapSink:
    """Channels and schemas on demand; :meth:`write` one decoded message (or raw bytes) per call."""

    def __init__(self, path: Path | None = None, *, stream=None, library: str = "lamps") -> None:
        """A new MCAP file at ``path``, or into the open binary ``stream`` (not closed by :meth:`finish`)."""
        self.path = path
        self._own = stream is None
        self._f = _Counted(open(path, "wb") if stream is None else stream)
        self._w = Writer(self._f, chunk_size=CHUNK_BYTES)
        self._last_flush = time.monotonic()
        self._w.start(profile="", library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: Counter[str] = Counter()

    def _schema(self, name: str, schema: dict) -> int:
        if name not in self._schemas:
            self._schemas[name] = self._w.register_schema(name=name, encoding="jsonschema",
                                                          data=json.dumps(schema).encode())
        return self._schemas[name]

    def _channel(self, topic: str, schema_name: str, schema: dict) -> int:
        if topic not in self._channels:
            self._channels[topic] = self._w.register_channel(topic=topic, message_encoding="json",
                                                             schema_id=self._schema(schema_name, schema))
        return self._channels[topic]

    def write_typed(self, topic: str, msg, t_ns: int) -> None:
        """One Foxglove typed message (``foxglove.messages.*``) on ``topic``, protobuf with the SDK's schema."""
        if topic not in self._channels:
            schema = type(msg).get_schema()
            if schema.name not in self._schemas:
                self._schemas[schema.name] = self._w.register_schema(name=schema.name, encoding=schema.encoding,
                                                                     data=bytes(schema.data))
            self._channels[topic] = self._w.register_channel(topic=topic, message_encoding=schema.encoding,
                                                             schema_id=self._schemas[schema.name])
        self._seq[topic] += 1
        self._w.add_message(channel_id=self._channels[topic], log_time=t_ns, publish_time=t_ns,
                            sequence=self._seq[topic], data=msg.encode())

    def carry_over(self, path: Path) -> tuple[int, int]:
        """Write every complete message of the earlier recording ``path`` (finished or cut), with its own times and
        sequence numbers, channels and schemas merged by topic and name, streamed (a recording of hours never sits
        in memory); returns (messages written, the last one's log time [ns], 0 if none)."""
        from mcap.records import Channel as ChannelRecord
        from mcap.records import Schema as SchemaRecord

        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, tuple[int, str]] = {}
        n = last_ns = 0
        for rec in iter_records(path):
            if isinstance(rec, SchemaRecord):
                if rec.name not in self._schemas:
                    self._schemas[rec.name] = self._w.register_schema(name=rec.name, encoding=rec.encoding,
                                                                      data=rec.data)
                schema_ids[rec.id] = self._schemas[rec.name]
            elif isinstance(rec, ChannelRecord):
                if (rec.schema_id in schema_ids or rec.schema_id == 0) and rec.topic not in self._channels:
                    self._channels[rec.topic] = self._w.register_channel(
                        topic=rec.topic, message_encoding=rec.message_encoding,
                        schema_id=schema_ids.get(rec.schema_id, 0), metadata=rec.metadata)
                if rec.topic in self._channels:
                    channel_ids[rec.id] = (self._channels[rec.topic], rec.topic)
            elif rec.channel_id in channel_ids:  # a message
                ch, topic = channel_ids[rec.channel_id]
                self._w.add_message(channel_id=ch, log_time=rec.log_time, publish_time=rec.publish_time,
                                    sequence=rec.sequence, data=rec.data)
                self._seq[topic] = max(self._seq[topic], rec.sequence)
                n += 1
                last_ns = max(last_ns, rec.log_time)
        return n, last_ns

    def write_json(self, topic: str, schema_name: str, data: Any, t_ns: int, schema: dict | None = None) -> None:
        """One JSON message on ``topic``; ``schema`` (full properties) is needed the first time ``schema_name``
        is seen."""
        if schema_name not in self._schemas and schema is None:
            raise ValueError(f"{schema_name}: a channel needs its schema with properties the first time")
        ch = self._channel(topic, schema_name, schema or {})
        self._seq[topic] += 1
        self._w.add_message(channel_id=ch, log_time=t_ns, publish_time=t_ns, sequence=self._seq[topic],
                            data=msgspec.json.encode(data))

    def write(self, key: str, msg: Message, t_ns: int) -> None:
        """``msg`` received on ``key`` at ``t_ns``, as the JSON channels of :func:`json_records`."""
        for topic, name, schema, data, t in json_records(key, msg, t_ns):
            self.write_json(topic, name, data, t, None if name in self._schemas else schema())

    def bytes_written(self) -> int:
        """Bytes in the file so far (whole chunks; the open chunk is not counted until it is written out)."""
        return self._f.tell()

    def flush(self, every_s: float = 0.0) -> None:
        """Push the complete chunks written so far to the disk (at most every ``every_s``)."""
        now = time.monotonic()
        if now - self._last_flush >= every_s:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._last_flush = now

    def finish(self) -> None:
        self._w.finish()
        if self._own:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()


#: At most this many rejected samples per key are described on ``<key>/rejected`` (their size and the error,
#: never their bytes); the rest are only counted.
REJECTED_NOTES_PER_KEY = 100
#: The recording's disk budget [bytes] by default (``LAMPS_RECORD_MAX_MB`` sets it in MiB).
DEFAULT_BUDGET_BYTES = 4 * 1024**3
_REJECTED_SCHEMA = {"type": "object", "title": "lamps.Rejected",
                    "properties": {"error": {"type": "string"}, "bytes": {"type": "integer"},
                                   "rejected_so_far": {"type": "integer"}}}
_BUDGET_SCHEMA = {"type": "object", "title": "lamps.RecorderBudget",
                  "properties": {"budget_bytes": {"type": "integer"}, "message": {"type": "string"}}}


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


class Recorder:
    """Subscribes ``<prefix>/**`` on ``session`` and writes ``out_dir/recording.mcap`` until :meth:`close`.

    ``keys``: the cell's, or a sequence of cells' (a site's recording, ``lamps record --cells``: every cell's keys
    under their own prefixes, each cell's scene in its own frame tree, :func:`launch.scene.cell_frames`).

    It records what the cell's receivers accept: a sample that does not decode as its key's message (bad
    bytes, over the key's size bound, an unknown key) is counted (``undecodable``, ``unknown_key``) and only
    described, its size and the error, on ``<key>/rejected``, for its first :data:`REJECTED_NOTES_PER_KEY`
    samples. ``budget_bytes`` bounds the file: past it nothing more is recorded (counted as
    ``dropped_over_budget``), one ``recorder/budget`` message and an error in the log say so, and the file is
    finished as usual.
    """

    def __init__(self, session, keys: Keys | list[Keys], out_dir: Path, max_queue: int = 200_000,
                 budget_bytes: int = DEFAULT_BUDGET_BYTES, clock=time.time_ns) -> None:
        from .scene import cells_of, scenes_of

        self.cells = cells_of(keys)
        self.clock = clock  # log_time of a sample [ns]: the wall clock, or the network-free cell's robot clock
        self.budget_bytes = budget_bytes
        self.over_budget = False
        self.keys = self.cells[0]
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.partial = self.out_dir / (RECORDING + ".partial")
        self.counters: Counter[str] = Counter()
        self.sink = self._open_sink()
        self._queue: deque = deque(maxlen=max_queue)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._decoders: dict[str, tuple | None] = {}  # key -> (decoder, its cell's scene, its prefix's length)
        self._rejected: Counter[str] = Counter()
        self.scenes = scenes_of(self.cells)
        self.scene = self.scenes[self.keys.prefix]
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()
        self._subs = [session.declare_subscriber(f"{k.prefix}/**", self._on_sample) for k in self.cells]

    def _open_sink(self) -> McapSink:
        """The sink at ``recording.mcap.partial``, holding first whatever an earlier recorder of this folder
        recorded (its ``.partial`` if it died, else its finished file). The earlier file is replaced only once
        the copy is on the disk."""
        final = self.out_dir / RECORDING
        earlier = self.partial if self.partial.is_file() else final if final.is_file() else None
        if earlier is None:
            return McapSink(self.partial)
        fresh = self.partial.with_name(self.partial.name + ".new")
        sink = McapSink(fresh)
        n, last_ns = sink.carry_over(earlier)
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

    def _on_sample(self, sample) -> None:  # Zenoh thread: never waits
        if len(self._queue) == self._queue.maxlen:
            self.counters["dropped_queue_full"] += 1
        payload = sample.payload  # the in-process bus's payload is kept as it is (its message, decoded once)
        self._queue.append((str(sample.key_expr), payload if hasattr(payload, "decoded") else payload.to_bytes(),
                            self.clock()))
        if not self._wake.is_set():  # set once until the writer wakes (a set Event costs a lock and a notify)
            self._wake.set()

    def _decoder(self, key: str) -> tuple | None:
        """(decoder, scene, prefix length) of ``key``, None for a key of no message type."""
        if key not in self._decoders:
            from .scene import cell_of_key

            cell = cell_of_key(self.cells, key)
            t = message_type_of(cell, key) if cell is not None else None
            self._decoders[key] = (Decoder(t), self.scenes[cell.prefix], len(cell.prefix) + 1) if t is not None \
                else None
        return self._decoders[key]

    def _drain(self) -> None:
        while self._queue:
            key, data, t_ns = self._queue.popleft()
            if self.over_budget or self._check_budget(t_ns):
                self.counters["dropped_over_budget"] += 1
                continue
            entry = self._decoder(key)
            try:
                if entry is None:
                    raise MessageDecodeError("no message type for this key")
                dec, scene, after_prefix = entry
                msg = dec(data) if isinstance(data, bytes) else data.decoded(dec)
                self.sink.write(key, msg, t_ns)
                self.counters[key[after_prefix:]] += 1
                for topic, scene_msg in scene.on_message(key, msg, t_ns):
                    self.sink.write_typed(topic, scene_msg, t_ns)
            except MessageDecodeError as exc:
                self.counters["undecodable" if entry is not None else "unknown_key"] += 1
                self._rejected[key] += 1
                if self._rejected[key] <= REJECTED_NOTES_PER_KEY:
                    self.sink.write_json(key + "/rejected", "lamps.Rejected",
                                         {"error": str(exc)[:200], "bytes": len(data),
                                          "rejected_so_far": self._rejected[key]}, t_ns, _REJECTED_SCHEMA)

    def _check_budget(self, t_ns: int) -> bool:
        """True (and said once) when the file has reached its disk budget."""
        if self.sink.bytes_written() < self.budget_bytes:
            return False
        self.over_budget = True
        message = (f"the recording reached its disk budget of {self.budget_bytes / 1024**2:.0f} MiB "
                   "(LAMPS_RECORD_MAX_MB): nothing more is recorded in this run")
        log.error("%s", message)
        self.sink.write_json("recorder/budget", "lamps.RecorderBudget",
                             {"budget_bytes": self.budget_bytes, "message": message}, t_ns, _BUDGET_SCHEMA)
        return True

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(0.1)
            self._wake.clear()
            self._drain()
            self.sink.flush(FLUSH_S)

    def close(self) -> Path:
        """Stop, write what is queued, finish the file; returns the recording's final path."""
        for sub in self._subs:
            sub.undeclare()
        self._stop.set()
        self._wake.set()
        self._thread.join(60.0)
        self._drain()
        self.sink.finish()
        final = self.out_dir / RECORDING
        os.replace(self.partial, final)
        return final


def iter_records(path: Path):
    """Every complete Schema, Channel and Message record of the MCAP file ``path`` in file order, finished or
    not (its writer died): a tolerant stream read that stops at the first damaged or cut record, having yielded
    everything before it."""
    from mcap.exceptions import McapError
    from mcap.records import Channel as ChannelRecord
    from mcap.records import Message as MessageRecord
    from mcap.records import Schema as SchemaRecord
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, validate_crcs=True).records:
                if isinstance(record, (SchemaRecord, ChannelRecord, MessageRecord)):
                    yield record
        except (McapError, EOFError, ValueError, struct.error, zlib.error, zstd.ZstdError):
            return  # the cut: everything before it is whole (each chunk carries its own CRC)
        except Exception as exc:  # a damaged chunk can fail inside a decompressor in other ways
            log.warning("reading %s: stopped at %s: %s", path, type(exc).__name__, exc)


def recover_recording(partial: Path, final: Path) -> int:
    """Write ``final`` (atomically) with every message of the complete records of ``partial``, an unfinished MCAP
    (its writer died); returns how many messages were recovered. Reading stops at the first damaged or cut
    record; what came before it is kept. Streamed, like :meth:`McapSink.carry_over`, which it is."""
    from lampskit.atomic import write_atomic

    count = [0]

    def write(out) -> None:
        sink = McapSink(stream=out, library="lamps (recovered)")
        count[0], _ = sink.carry_over(partial)
        sink.finish()

    write_atomic(final, write)
    return count[0]


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
