"""The recording's MCAP file: written in small chunks, each message's share of the file charged to an account, and
read back up to the first damaged record when its writer died.

:class:`McapSink` writes JSON and Foxglove typed messages, registering channels and schemas on demand. Every
message is charged to the sink's current :attr:`McapSink.account` (the recorder sets it to the key whose
message it writes), so the recorder knows what each key takes of the disk: the bytes a chunk adds to the file
(compressed, with its index) are shared among the accounts of its messages in proportion to their size
(:meth:`McapSink.used`); the chunk still being built counts at the compression of the chunks before it.

:func:`iter_records` and :func:`recover_recording` read a file whose writer died (no summary, a cut chunk):
everything up to the first damaged record.
"""

from __future__ import annotations

import json
import logging
import os
import struct
import time
import zlib
from collections import Counter
from pathlib import Path
from typing import IO, Any, cast

import msgspec
import zstandard as zstd
from mcap.writer import Writer

from interfaces.messages import Message

from .record_json import json_records

log = logging.getLogger(__name__)

#: MCAP chunk size [bytes]: small, so a crash loses little (a chunk is on the disk only once complete).
CHUNK_BYTES = 256 * 1024
#: The recording is pushed to the disk this often [s].
FLUSH_S = 1.0
#: The account of what no key is charged with (the recorder's own messages, unless it says otherwise).
RECORDER_ACCOUNT = "recorder"


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
    """Channels and schemas on demand; :meth:`write` one decoded message (or raw bytes) per call, charged to
    :attr:`account`."""

    def __init__(self, path: Path | None = None, *, stream=None, library: str = "lamps") -> None:
        """A new MCAP file at ``path``, or into the open binary ``stream`` (not closed by :meth:`finish`)."""
        self.path = path
        self._own = stream is None
        if stream is None:
            if path is None:
                raise ValueError("McapSink needs a path or a stream")
            stream = open(path, "wb")  # closed by finish()
        self._f = _Counted(stream)
        self._w = Writer(cast(IO[bytes], self._f), chunk_size=CHUNK_BYTES)  # _Counted: a binary stream that counts
        self._last_flush = time.monotonic()
        self._w.start(profile="", library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: Counter[str] = Counter()
        #: the account the next messages are charged to (:meth:`used`)
        self.account = RECORDER_ACCOUNT
        self._charged: Counter[str] = Counter()  # file bytes of whole chunks, per account
        self._open: Counter[str] = Counter()  # message bytes in the chunk being built, per account
        self._pos_charged = self._f.tell()
        self._done_bytes = (0, 0)  # message bytes of the chunks written so far, and what they took of the file
        self._ratio = 1.0  # file bytes per message byte of the chunks written so far

    def _add(self, channel_id: int, log_time: int, publish_time: int, sequence: int, data: bytes) -> None:
        self._open[self.account] += len(data)
        self._w.add_message(channel_id=channel_id, log_time=log_time, publish_time=publish_time,
                            sequence=sequence, data=data)
        pos = self._f.tell()
        if pos != self._pos_charged:  # a chunk went to the file: share its bytes among its messages' accounts
            grown, total = pos - self._pos_charged, max(sum(self._open.values()), 1)
            for account, n in self._open.items():
                self._charged[account] += grown * n // total
            self._done_bytes = (self._done_bytes[0] + total, self._done_bytes[1] + grown)
            self._ratio = self._done_bytes[1] / self._done_bytes[0]
            self._open.clear()
            self._pos_charged = pos

    def used(self, account: str) -> int:
        """What ``account`` takes of the file so far [bytes]: its part of every whole chunk, and its messages in
        the chunk being built at the file's compression so far."""
        return self._charged[account] + int(self._open[account] * self._ratio)

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
        self._add(self._channels[topic], t_ns, t_ns, self._seq[topic], msg.encode())

    def carry_over(self, path: Path, account_of=None) -> tuple[int, int]:
        """Write every complete message of the earlier recording ``path`` (finished or cut), with its own times and
        sequence numbers, channels and schemas merged by topic and name, streamed (a recording of hours never sits
        in memory); returns (messages written, the last one's log time [ns], 0 if none). ``account_of(topic)``:
        the account each message is charged to (None: the current one)."""
        from mcap.records import Channel as ChannelRecord
        from mcap.records import Schema as SchemaRecord

        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, tuple[int, str, str]] = {}
        n = last_ns = 0
        current = self.account
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
                    account = account_of(rec.topic) if account_of is not None else None
                    channel_ids[rec.id] = (self._channels[rec.topic], rec.topic, account or current)
            elif rec.channel_id in channel_ids:  # a message
                ch, topic, self.account = channel_ids[rec.channel_id]
                self._add(ch, rec.log_time, rec.publish_time, rec.sequence, rec.data)
                self._seq[topic] = max(self._seq[topic], rec.sequence)
                n += 1
                last_ns = max(last_ns, rec.log_time)
        self.account = current
        return n, last_ns

    def write_json(self, topic: str, schema_name: str, data: Any, t_ns: int, schema: dict | None = None) -> None:
        """One JSON message on ``topic``; ``schema`` (full properties) is needed the first time ``schema_name``
        is seen."""
        if schema_name not in self._schemas and schema is None:
            raise ValueError(f"{schema_name}: a channel needs its schema with properties the first time")
        ch = self._channel(topic, schema_name, schema or {})
        self._seq[topic] += 1
        self._add(ch, t_ns, t_ns, self._seq[topic], msgspec.json.encode(data))

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
