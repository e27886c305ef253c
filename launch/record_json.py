"""What one cell message becomes in a recording (:mod:`launch.record`) and in the live view (:mod:`launch.live`):
the message type of each key, the message as plain JSON-able data, and the JSON channel messages it makes (camera
frames as ``foxglove.CompressedImage`` with their pose and intrinsics on ``<key>/info``, every other message as
``lamps.<Type>``, and a controller trace batch also as plottable rows on ``<key>/plot``)."""

from __future__ import annotations

import base64
from typing import Any

import cv2
import msgspec
import numpy as np

from interfaces.keys import Keys
from interfaces.messages import (
    ArmRequest,
    CameraFrame,
    ControllerStatus,
    ControllerTrace,
    Estop,
    Introduction,
    Message,
    RobotState,
    ServiceStatus,
    SimTruth,
    Stains,
    TorqueCommand,
)
from launch.schemas import json_schema_of

_COMPRESSED_IMAGE_SCHEMA = {
    "type": "object",
    "title": "foxglove.CompressedImage",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string"},
    },
}


def message_type_of(keys: Keys, key: str) -> type[Message] | None:
    """The message type published on ``key`` (None for keys the contract does not define)."""
    table: dict[str, type[Message]] = {
             keys.robot_state: RobotState, keys.robot_command: TorqueCommand, keys.perception_stains: Stains,
             keys.perception_status: ServiceStatus, keys.perception_debug: CameraFrame,
             keys.controller_status: ControllerStatus, keys.controller_trace: ControllerTrace,
             keys.controller_estop: Estop, keys.controller_estop_release: Estop, keys.sim_truth: SimTruth,
             keys.sim_status: ServiceStatus, keys.robot_status: ServiceStatus, keys.robot_arm: ArmRequest,
             keys.robot_introduction: Introduction, keys.controller_introduction: Introduction}
    if key in table:
        return table[key]
    cam = keys.camera_frame("x")[:-len("x/frame")]
    if key.startswith(cam) and key.endswith("/frame"):
        return CameraFrame
    return None


#: Values that stay as they are (exact types: checked without a call per value, the 1 kHz messages' many floats).
_PLAIN = frozenset((float, int, str, bool, type(None)))


def to_builtins(msg: Any) -> Any:
    """A message as plain JSON-able data with field names (array-like structs become objects)."""
    if isinstance(msg, msgspec.Struct):
        return {f: v if type(v) in _PLAIN else to_builtins(v)
                for f, v in zip(msg.__struct_fields__, msgspec.structs.astuple(msg))}
    if isinstance(msg, (list, tuple)):
        return [v if type(v) in _PLAIN else to_builtins(v) for v in msg]
    if isinstance(msg, dict):
        return {str(k): to_builtins(v) for k, v in msg.items()}
    if isinstance(msg, (bytes, bytearray, memoryview)):
        return base64.b64encode(bytes(msg)).decode("ascii")
    return msg


def _jpeg_of(frame: CameraFrame) -> bytes | None:
    from perception.frames import FrameError, rgb_from_message
    try:
        rgb = rgb_from_message(frame)
    except FrameError:
        return None
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
    return buf.tobytes() if ok else None


#: The controller trace is also written as plottable rows, every this many ticks (100 Hz at 1 kHz).
TRACE_PLOT_EVERY = 10
TRACE_PLOT_SCHEMA_NAME = "lamps.ControllerTraceRow"


def _camera_info_schema() -> dict:
    schema = json_schema_of(CameraFrame, drop=("data",))
    schema["title"] = "lamps.CameraFrameInfo"
    return schema


def json_records(key: str, msg: Message, t_ns: int):
    """The JSON channel messages one cell message makes: (topic, schema name, schema (a callable: built only
    when a channel is new), JSON-able data, log time [ns]).

    Camera frames -> ``foxglove.CompressedImage`` (JPEG) on the key and their pose and intrinsics on
    ``<key>/info``; every other message -> ``lamps.<Type>`` on its key; a controller trace batch also -> every
    :data:`TRACE_PLOT_EVERY`-th tick on ``<key>/plot``. The recorder and the live view (``lamps foxglove``) both
    use it, so what Foxglove shows live is what the recording holds.
    """
    if isinstance(msg, CameraFrame):
        from .scene import camera_frame_id

        jpeg = _jpeg_of(msg)
        stamp = t_ns  # the receipt time, the clock of the scene's transforms and overlays (the robot's is in /info)
        if jpeg is not None:
            yield (key, "foxglove.CompressedImage", lambda: _COMPRESSED_IMAGE_SCHEMA,
                   {"timestamp": {"sec": stamp // 10**9, "nsec": stamp % 10**9},
                    "frame_id": camera_frame_id(msg.camera),
                    "data": base64.b64encode(jpeg).decode("ascii"), "format": "jpeg"}, t_ns)
        info = {f: v if type(v) in _PLAIN else to_builtins(v)  # all but the pixels (never base64-encoded to be dropped)
                for f, v in zip(msg.__struct_fields__, msgspec.structs.astuple(msg)) if f != "data"}
        yield key + "/info", "lamps.CameraFrameInfo", _camera_info_schema, info, t_ns
        return
    name = f"lamps.{type(msg).__name__}"
    yield key, name, lambda: json_schema_of(type(msg)), to_builtins(msg), t_ns
    if isinstance(msg, ControllerTrace):
        yield from _trace_rows(key, msg, t_ns)


def _trace_rows(key: str, msg: ControllerTrace, t_ns: int):
    """Every :data:`TRACE_PLOT_EVERY`-th tick of a trace batch as its own message on ``<key>/plot``, one number
    per column (a series Foxglove's Plot panel draws; the batch itself stays the full record)."""
    cols = list(msg.columns)
    n = len(cols)
    if n == 0 or msg.n_rows <= 0 or len(msg.data) != 8 * n * msg.n_rows:
        return
    rows = np.frombuffer(msg.data, "<f8").reshape(msg.n_rows, n)

    def schema() -> dict:
        return {"type": "object", "title": TRACE_PLOT_SCHEMA_NAME,
                "properties": {"tick": {"type": "integer"}, **{c: {"type": "number"} for c in cols}}}

    t = rows[:, cols.index("t_s")] if "t_s" in cols else None
    start = (-msg.first_tick) % TRACE_PLOT_EVERY
    for k in range(start, msg.n_rows, TRACE_PLOT_EVERY):
        # a value that is not finite is left out (a gap in the plot): JSON has no NaN, and a plain "number" type
        # is what Foxglove / Lichtblick build a plottable field from (a ["number", "null"] union is not)
        row: dict[str, float] = {"tick": msg.first_tick + k}
        row.update((c, float(v)) for c, v in zip(cols, rows[k]) if np.isfinite(v))
        # each row at its own time: the batch's receipt less how much earlier the tick was (controller clock)
        back_ns = int((t[-1] - t[k]) * 1e9) if t is not None and np.isfinite(t[-1] - t[k]) else 0
        yield key + "/plot", TRACE_PLOT_SCHEMA_NAME, schema, row, max(t_ns - max(back_ns, 0), 0)
