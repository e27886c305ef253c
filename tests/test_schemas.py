"""Recorded channels carry JSON schemas with every property (Foxglove / Lichtblick drop those without)."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest

from interfaces.messages import (
    ArmRequest,
    Capabilities,
    ControllerStatus,
    ControllerTrace,
    Estop,
    RobotState,
    ServiceStatus,
    SimTruth,
    Stains,
    TorqueCommand,
)
from launch.record import McapSink, read_recording
from launch.record_json import to_builtins
from launch.schemas import json_schema_of

TYPES = (RobotState, TorqueCommand, Stains, ServiceStatus, ControllerStatus, ControllerTrace, Estop, SimTruth,
         ArmRequest)


@pytest.mark.parametrize("cls", TYPES, ids=lambda c: c.__name__)
def test_every_message_type_has_a_schema_naming_each_field(cls):
    schema = json_schema_of(cls)
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["title"] == f"lamps.{cls.__name__}" and set(schema["properties"]) == set(cls.__struct_fields__)


def _state() -> RobotState:
    return RobotState(seq=3, stamp_ns=1, q_rad=[0.1] * 7, dq_rad_s=[0.0] * 7, tau_nm=[1.0] * 7,
                      wrench_world=[0.0] * 6, capabilities=Capabilities(True, [100.0] * 7, "sim", 1000.0),
                      robot_time_ns=5, wall_ns=6, command_seq=2)


def test_a_recorded_message_validates_and_a_wrong_one_does_not():
    v = jsonschema.Draft202012Validator(json_schema_of(RobotState))
    good = to_builtins(_state())
    v.validate(good)
    assert good["capabilities"]["torque_limits_nm"] == [100.0] * 7, "nested messages are objects with names"
    for field, bad in (("q_rad", "0.1"), ("seq", 1.5), ("capabilities", [True, [1.0], "sim", 1.0])):
        with pytest.raises(jsonschema.ValidationError):
            v.validate({**good, field: bad})
    with pytest.raises(jsonschema.ValidationError):
        v.validate({k: x for k, x in good.items() if k != "q_rad"})
    trace = ControllerTrace(seq=1, stamp_ns=2, columns=["t_s"], first_tick=0, n_rows=1,
                            data=np.zeros(1).tobytes())
    jsonschema.validate(to_builtins(trace), json_schema_of(ControllerTrace))  # bytes as base64 text


def test_the_recording_holds_the_schemas_with_properties(tmp_path):
    from mcap.reader import make_reader

    path = tmp_path / "r.mcap"
    sink = McapSink(path)
    sink.write("lamps/x/robot/state", _state(), 10)
    sink.write("lamps/x/controller/estop", Estop(stamp_ns=1, engaged=True, reason="test", source="op"), 11)
    with pytest.raises(ValueError, match="needs its schema"):
        sink.write_json("lamps/x/other", "lamps.Unknown", {"a": 1}, 12)
    sink.finish()
    with open(path, "rb") as f:
        seen = {}
        for schema, channel, message in make_reader(f).iter_messages():
            s = json.loads(schema.data)
            assert s["properties"], channel.topic
            jsonschema.validate(json.loads(message.data), s)
            seen[channel.topic] = schema.name
    assert seen == {"lamps/x/robot/state": "lamps.RobotState", "lamps/x/controller/estop": "lamps.Estop"}
    assert read_recording(path)["lamps/x/robot/state"][0][1]["command_seq"] == 2


def test_the_controller_trace_is_also_written_as_plottable_rows(tmp_path):
    from mcap.reader import make_reader

    from launch.record_json import TRACE_PLOT_EVERY

    cols = ["t_s", "phase", "force_n"]
    n = 45
    rows = np.column_stack([0.5 + np.arange(n) * 1e-3, np.full(n, 3.0), np.linspace(9.0, 11.0, n)])
    rows[7, 2] = np.nan  # tick 110, a plotted one: left out of its row (a gap in the plot)
    path = tmp_path / "t.mcap"
    sink = McapSink(path)
    sink.write("lamps/x/controller/trace", ControllerTrace(seq=1, stamp_ns=1, columns=cols, first_tick=103,
                                                           n_rows=n, data=rows.astype("<f8").tobytes()), 10**12)
    sink.finish()
    plot = []
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
            if channel.topic.endswith("/plot"):
                plot.append((message.log_time, json.loads(message.data)))
    ticks = [m["tick"] for _, m in plot]
    assert ticks == list(range(110, 103 + n, TRACE_PLOT_EVERY)), ticks  # every 10th tick of the controller
    for log_time, m in plot:
        k = m["tick"] - 103
        assert ("force_n" not in m) if np.isnan(rows[k, 2]) else m["force_n"] == pytest.approx(rows[k, 2])
        assert m["phase"] == 3.0
        assert log_time == pytest.approx(10**12 - (rows[-1, 0] - rows[k, 0]) * 1e9, abs=2)  # at its own time
    assert read_recording(path)["lamps/x/controller/trace"][0][1]["n_rows"] == n, "the full batch is kept"
