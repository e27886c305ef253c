"""Property-based fuzzing (hypothesis) of every decoder and every file reader: any input gives a value or the
project's own error naming the problem, never another exception.

Messages: random bytes, and valid payloads with one field of the wire array replaced by an arbitrary msgpack
value (the shapes an attacker can reach). Files: demonstrations (CSV, TSV, NPZ bytes), skill files (JSON text
and JSON trees built around the real skill's keys), configs (TOML text, and TOML tables of random values).
"""

from __future__ import annotations

import json
import string

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from interfaces.codec import Decoder, encode
from interfaces.errors import ConfigError, MessageDecodeError
from interfaces.messages import MESSAGE_TYPES
from lampskit.core.skill import load_skill
from lampskit.errors import LampsError
from lampskit.learn.demo_io import read_demo
from runtime.config import load_config

from .test_interfaces_messages import samples

EXAMPLES = samples()

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

def _value_or(error: type[Exception], read, *args) -> None:
    """``read(*args)`` returns a value or raises ``error`` (the project's own, naming the problem); anything else
    propagates and fails the test."""
    try:
        read(*args)
    except error:
        pass


msgpack_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**63, 2**64 - 1) | st.floats() | st.text(max_size=40)
    | st.binary(max_size=40),
    lambda inner: st.lists(inner, max_size=8) | st.dictionaries(st.text(max_size=8), inner, max_size=8),
    max_leaves=30)


@pytest.mark.parametrize("msg_type", MESSAGE_TYPES, ids=lambda t: t.__name__)
@FUZZ
@given(data=st.binary(max_size=2048))
def test_random_bytes_decode_to_a_message_or_a_decode_error(msg_type, data):
    _value_or(MessageDecodeError, Decoder(msg_type), data)


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda m: type(m).__name__)
@FUZZ
@given(index=st.integers(0, 40), value=msgpack_values)
def test_a_valid_message_with_one_field_replaced_decodes_or_is_refused(example, index, value):
    wire = msgspec.msgpack.decode(encode(example))
    wire[index % len(wire)] = value
    _value_or(MessageDecodeError, Decoder(type(example)), msgspec.msgpack.encode(wire))


def _read(tmp_path, name: str, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


@FUZZ
@given(text=st.text(alphabet=string.printable, max_size=600))
def test_any_csv_or_tsv_text_is_a_demo_or_a_demo_error(tmp_path, text):
    for name in ("d.csv", "d.tsv"):
        _value_or(LampsError, read_demo, _read(tmp_path, name, text.encode()))


@FUZZ
@given(header=st.lists(st.sampled_from(["t", "x", "y", "z", "time", "a", ""]), min_size=1, max_size=5),
       rows=st.lists(st.lists(st.one_of(st.floats(), st.text(alphabet="0123456789.-eE", max_size=6)), min_size=1,
                              max_size=5), max_size=40))
def test_csv_shaped_files_are_a_demo_or_a_demo_error(tmp_path, header, rows):
    text = ",".join(header) + "\n" + "".join(",".join(str(v) for v in r) + "\n" for r in rows)
    _value_or(LampsError, read_demo, _read(tmp_path, "d.csv", text.encode()))


@FUZZ
@given(data=st.binary(max_size=600))
def test_any_npz_bytes_are_a_demo_or_a_demo_error(tmp_path, data):
    _value_or(LampsError, read_demo, _read(tmp_path, "d.npz", data))


@pytest.fixture(scope="module")
def skill_tree(learned_skill_file):
    return json.loads(learned_skill_file.read_text())


def _mutate(tree, path: list[int], value):
    """``tree`` with the node reached by ``path`` (indices into dict values / list items, modulo) replaced."""
    if not path or not isinstance(tree, (dict, list)) or not tree:
        return value
    if isinstance(tree, dict):
        keys = list(tree)
        k = keys[path[0] % len(keys)]
        return {**tree, k: _mutate(tree[k], path[1:], value)}
    i = path[0] % len(tree)
    return [*tree[:i], _mutate(tree[i], path[1:], value), *tree[i + 1:]]


json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False)
                           | st.text(max_size=10),
                           lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                                       max_size=4), max_leaves=12)


@FUZZ
@given(path=st.lists(st.integers(0, 50), max_size=6), value=json_values)
def test_a_skill_file_with_any_node_replaced_loads_or_is_a_skill_file_error(tmp_path, skill_tree, path, value):
    _value_or(LampsError, load_skill, _read(tmp_path, "s.json", json.dumps(_mutate(skill_tree, path, value)).encode()))


@FUZZ
@given(data=st.binary(max_size=400))
def test_any_skill_file_bytes_load_or_are_a_skill_file_error(tmp_path, data):
    _value_or(LampsError, load_skill, _read(tmp_path, "s.json", data))


@FUZZ
@given(text=st.text(max_size=400))
def test_any_config_text_loads_or_is_a_config_error(tmp_path, text):
    _value_or(ConfigError, load_config, _read(tmp_path, "c.toml", text.encode()), {})


toml_scalars = st.one_of(st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=False, allow_infinity=False),
                         st.text(alphabet=string.ascii_letters + "/:.", max_size=20))


@FUZZ
@given(section=st.sampled_from(["zenoh", "sim", "controller", "perception"]),
       key=st.sampled_from(["mode", "listen", "connect", "robot_id", "user", "access_control", "rate_hz", "seed",
                            "board", "skill", "nonsense"]),
       value=st.one_of(toml_scalars, st.lists(toml_scalars, max_size=3)))
def test_a_config_with_any_value_in_a_known_place_loads_or_is_a_config_error(tmp_path, section, key, value):
    text = f"[{section}]\n{key} = {json.dumps(value)}\n"
    _value_or(ConfigError, load_config, _read(tmp_path, "c.toml", text.encode()), {})
