"""Every message of a recording checked against its channel's schema: JSON Schema, or protobuf (Foxglove's types).

What the Foxglove / Lichtblick decoders need: a JSON channel's schema names
its properties and the message validates against it; a protobuf channel's
schema is a FileDescriptorSet that holds the message type, and the message
parses as that type.
"""

from __future__ import annotations

import json
from pathlib import Path


def protobuf_class(name: str, data: bytes):
    """The protobuf message class ``name`` from a serialized FileDescriptorSet ``data`` (a recording's schema)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(data)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


def check_recording(path: Path, every: int = 20) -> dict[str, tuple[str, int]]:
    """topic -> (schema name, messages); every ``every``-th message of each channel (and the first) checked.

    Raises AssertionError naming the channel whose schema or message is wrong.
    """
    import jsonschema
    from mcap.reader import make_reader

    checks, seen, names = {}, {}, {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            topic = channel.topic
            if topic not in checks:
                assert schema is not None, f"{topic}: no schema"
                names[topic] = schema.name
                if channel.message_encoding == "json":
                    s = json.loads(schema.data)
                    assert s.get("properties"), f"{topic}: schema {schema.name} has no properties"
                    # Lichtblick builds no field from a type union ("type": [...]): such a field cannot be plotted
                    assert '"type": [' not in json.dumps(s), f"{topic}: schema {schema.name} has a type union"
                    v = jsonschema.Draft202012Validator(s)
                    checks[topic] = lambda data, v=v: v.validate(json.loads(data))
                else:
                    assert channel.message_encoding == schema.encoding == "protobuf", \
                        f"{topic}: encoding {channel.message_encoding} with a {schema.encoding} schema"
                    cls = protobuf_class(schema.name, schema.data)

                    def parse(data, cls=cls, topic=topic):
                        m = cls.FromString(data)
                        assert m.ListFields(), f"{topic}: an empty {cls.DESCRIPTOR.full_name}"
                    checks[topic] = parse
            seen[topic] = seen.get(topic, 0) + 1
            if seen[topic] % every == 1:
                checks[topic](message.data)
    return {t: (names[t], n) for t, n in seen.items()}


def check_layout_against(path: Path, layout: dict) -> None:
    """Every topic the Foxglove layout shows is in the recording, and every plotted field is in its messages."""
    from mcap.reader import make_reader

    from launch.layout import layout_paths

    topics, paths = layout_paths(layout)
    first: dict[str, dict] = {}
    present: set[str] = set()
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            present.add(channel.topic)
            if channel.message_encoding == "json" and channel.topic not in first:
                first[channel.topic] = json.loads(message.data)
    missing = sorted(topics - present)
    assert not missing, f"the layout shows topics the recording does not have: {missing}"
    for topic, field, index in paths:
        msg = first.get(topic)
        assert msg is not None and field in msg, f"layout path {topic}.{field}: no such field"
        if index is not None:
            assert isinstance(msg[field], list) and index < len(msg[field]), f"layout path {topic}.{field}[{index}]"
