"""Bytes <-> messages. One exception for everything that is not a valid message.

``encode(msg) -> bytes`` and ``decode(data, RobotState) -> RobotState``;
:class:`Decoder` is the reusable form for a hot loop (one msgspec decoder
built once). Any failure, garbage, truncation, another message type, another
schema version, a value out of range, a payload larger than its type may be
(refused before parsing), raises
:class:`~interfaces.errors.MessageDecodeError` whose text names the problem.
"""

from __future__ import annotations

from typing import Generic, TypeVar

import msgspec

from .errors import MessageDecodeError
from .messages import MAX_PAYLOAD_BYTES, SCHEMA_VERSION, Message

M = TypeVar("M", bound=Message)

_encoder = msgspec.msgpack.Encoder()


def encode(msg: Message) -> bytes:
    """The msgpack bytes of ``msg``."""
    return _encoder.encode(msg)


class Decoder(Generic[M]):
    """Decodes payloads of one message type; build once, call per sample."""

    def __init__(self, msg_type: type[M]) -> None:
        self.msg_type = msg_type
        self._decoder = msgspec.msgpack.Decoder(msg_type)
        #: payloads larger than this [bytes] are refused unparsed (:data:`~interfaces.messages.MAX_PAYLOAD_BYTES`)
        self.max_bytes = MAX_PAYLOAD_BYTES.get(msg_type, 1_048_576)

    def check_size(self, n_bytes: int) -> None:
        """Raise MessageDecodeError for a payload of ``n_bytes`` larger than this type may be (nothing parsed)."""
        if n_bytes > self.max_bytes:
            raise MessageDecodeError(f"oversized {self.msg_type.__name__} payload: {n_bytes} bytes > "
                                     f"{self.max_bytes}, not parsed")

    def __call__(self, data: bytes | bytearray | memoryview) -> M:
        self.check_size(len(data))
        try:
            msg = self._decoder.decode(data)
        except Exception as exc:  # any failure (incl. RecursionError on absurd nesting) is a bad payload
            raise MessageDecodeError(self._explain(data, exc)) from None
        if msg.version != SCHEMA_VERSION:
            raise MessageDecodeError(
                f"{self.msg_type.__name__}: schema version {msg.version}, this build reads {SCHEMA_VERSION}"
            )
        return msg

    def _explain(self, data, exc: Exception) -> str:
        """Say *why* the bytes are not a valid message: other type, other version, or the decoder's reason."""
        name = self.msg_type.__name__
        try:
            raw = msgspec.msgpack.decode(data)
        except Exception:
            return f"{name}: not a msgpack message ({type(exc).__name__}: {str(exc)[:120]})"
        # wire layout: [type tag, fields..., version] (msgspec puts the base's default field last)
        if isinstance(raw, list) and len(raw) >= 2 and isinstance(raw[0], str):
            if raw[0] != name:
                return f"expected a {name}, got a {raw[0]}"
            if raw[-1] != SCHEMA_VERSION:
                return f"{name}: schema version {raw[-1]!r}, this build reads {SCHEMA_VERSION}"
        return f"{name}: {exc}"


def decode(data: bytes | bytearray | memoryview, msg_type: type[M]) -> M:
    """Decode one payload as ``msg_type`` (builds a decoder; use :class:`Decoder` in loops)."""
    return Decoder(msg_type)(data)
