"""What the cell's messages (:mod:`interfaces.messages`) check beyond their types: the longest strings and counter
maps a message may carry (a longer one fails to decode; producers' statuses are clipped to them on construction),
and the finiteness and length checks their ``__post_init__`` runs (on decode too)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated

import msgspec
from msgspec.structs import force_setattr

#: Longest strings a message may carry (a longer one fails to decode: dropped and counted). Producers' statuses
#: are clipped to them on construction, so no input can make a status grow.
NAME_MAX = 64
TEXT_MAX = 512
DETAIL_MAX = 1024
COUNTER_KEY_MAX = 160
COUNTERS_MAX = 256
Name = Annotated[str, msgspec.Meta(max_length=NAME_MAX)]
Text = Annotated[str, msgspec.Meta(max_length=TEXT_MAX)]
Detail = Annotated[str, msgspec.Meta(max_length=DETAIL_MAX)]
#: A command's MAC, a nonce, a certificate (PEM) and an ECDSA signature (DER): bounded bytes (interfaces.arm_auth).
Mac = Annotated[bytes, msgspec.Meta(max_length=32)]
Nonce = Annotated[bytes, msgspec.Meta(max_length=32)]
Certificate = Annotated[bytes, msgspec.Meta(max_length=4096)]
Signature = Annotated[bytes, msgspec.Meta(max_length=160)]
Counters = Annotated[dict[Annotated[str, msgspec.Meta(max_length=COUNTER_KEY_MAX)], int],
                     msgspec.Meta(max_length=COUNTERS_MAX)]


def bounded_counters(counters: dict[str, int]) -> dict[str, int]:
    """``counters`` with keys clipped to :data:`COUNTER_KEY_MAX` and at most :data:`COUNTERS_MAX` entries (the rest
    summed into ``"other counters"``)."""
    if len(counters) <= COUNTERS_MAX and all(len(k) <= COUNTER_KEY_MAX for k in counters):
        return counters
    out: dict[str, int] = {}
    for k, v in counters.items():
        k = k[:COUNTER_KEY_MAX]
        if k in out or len(out) < COUNTERS_MAX - 1:
            out[k] = out.get(k, 0) + v
        else:
            out["other counters"] = out.get("other counters", 0) + v
    return out


def clip_strings(msg, **limits: int) -> None:
    """Clip the named string fields of a just-built (frozen) message to their limits."""
    for name, limit in limits.items():
        value = getattr(msg, name)
        if len(value) > limit:
            force_setattr(msg, name, value[:limit])


def check_finite(name: str, values: Sequence[float], length: int | None = None) -> None:
    """Raise ValueError unless every one of ``values`` is finite (and, given ``length``, there are that many)."""
    if length is not None and len(values) != length:
        raise ValueError(f"{name} must hold {length} numbers, got {len(values)}")
    for v in values:
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")


def check_same_length(names: Sequence[str], vectors: Sequence[Sequence[float]]) -> None:
    """Raise ValueError unless every one of ``vectors`` (named by ``names``, in order) is as long as the first."""
    n = len(vectors[0])
    for name, v in zip(names, vectors):
        if len(v) != n:
            raise ValueError(f"{name} has {len(v)} entries but {names[0]} has {n}")
