"""JSON schemas with every property, for the recorded channels, so Foxglove and Lichtblick decode them.

The open-source Foxglove / Lichtblick JSON decoders drop a channel whose
``jsonschema`` has no ``properties``. :func:`json_schema_of` derives a full
schema from a message type's declaration (``msgspec.inspect``): every field
with its JSON type, nested messages as objects (the recorder writes array-like
structs with field names, :func:`launch.record_json.to_builtins`), lists with their
item schema, bytes as base64 strings, optional fields as ``anyOf`` with
``null``, and ``required`` for the fields without a default. String length
bounds are kept; numeric bounds are not (a schema for viewers, not a second
validator of the contract).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import msgspec
import msgspec.inspect as mi


def _schema(t: mi.Type) -> dict[str, Any]:
    if isinstance(t, mi.StructType):
        return _struct(t.cls)
    if isinstance(t, mi.BoolType):
        return {"type": "boolean"}
    if isinstance(t, mi.IntType):
        return {"type": "integer"}
    if isinstance(t, mi.FloatType):
        return {"type": "number"}
    if isinstance(t, mi.StrType):
        out: dict[str, Any] = {"type": "string"}
        if t.max_length is not None:
            out["maxLength"] = t.max_length
        return out
    if isinstance(t, (mi.BytesType, mi.ByteArrayType, mi.MemoryViewType)):
        return {"type": "string", "contentEncoding": "base64"}
    if isinstance(t, (mi.ListType, mi.VarTupleType, mi.SetType, mi.FrozenSetType)):
        return {"type": "array", "items": _schema(t.item_type)}
    if isinstance(t, mi.TupleType):
        return {"type": "array", "prefixItems": [_schema(x) for x in t.item_types], "minItems": len(t.item_types),
                "maxItems": len(t.item_types)}
    if isinstance(t, mi.DictType):
        return {"type": "object", "additionalProperties": _schema(t.value_type)}
    if isinstance(t, mi.NoneType):
        return {"type": "null"}
    if isinstance(t, mi.LiteralType):
        return {"enum": list(t.values)}
    if isinstance(t, mi.EnumType):
        return {"enum": [m.value for m in t.cls]}
    if isinstance(t, mi.UnionType):
        return {"anyOf": [_schema(x) for x in t.types]}
    if isinstance(t, mi.Metadata):
        return _schema(t.type)
    if isinstance(t, mi.AnyType):
        return {}
    raise TypeError(f"no JSON schema for the message field type {t!r}")


def _struct(cls: type) -> dict[str, Any]:
    info = mi.type_info(cls)
    if not isinstance(info, mi.StructType):
        raise TypeError(f"no JSON schema for {cls!r}: not a message (a msgspec Struct)")
    props = {f.name: _schema(f.type) for f in info.fields}
    required = [f.name for f in info.fields if f.required]
    out: dict[str, Any] = {"type": "object", "title": f"lamps.{cls.__name__}", "properties": props}
    if required:
        out["required"] = required
    return out


@cache
def _cached(cls: type) -> str:
    return msgspec.json.encode(_struct(cls)).decode()


def json_schema_of(cls: type, drop: tuple[str, ...] = ()) -> dict[str, Any]:
    """The JSON schema (a fresh dict) of message type ``cls`` as the recorder writes it, without ``drop`` fields.

    Raises TypeError for a field type that has no JSON form.
    """
    schema = msgspec.json.decode(_cached(cls))
    for name in drop:
        schema["properties"].pop(name, None)
        if name in schema.get("required", []):
            schema["required"].remove(name)
    return schema
