"""Demonstrations from robot recordings: rosbag2 folders (MCAP or sqlite3 storage), MCAP files, the cell's recording.

What is read (one topic, ``--topic``, else the only topic of the first kind the recording holds, in this order):

- ``lbr_fri_idl/msg/LBRState`` (the lbr stack's ``/lbr/state``): ``measured_joint_position``, joints A1..A7 in
  order (lbr_fri_ros2_stack ``rolling`` 218d723, lbr_ros2_control/src/controllers/lbr_state_broadcaster.cpp:73-94
  fills the arrays over the joint names that lines 153-162 build as ``<robot_name>_A1..7``), stamped by
  ``time_stamp_sec`` / ``time_stamp_nano_sec`` (the robot's FRI time, same file lines 65-68);
- ``sensor_msgs/msg/JointState`` (``/lbr/joint_states``): the arm's joints picked by name (extra joints, e.g. a
  gripper's, are ignored; another robot's names are refused), stamped by its header;
- the cell's own ``recording.mcap`` (JSON ``lamps.RobotState`` on ``<prefix>/robot/state``): ``q_rad`` in the
  arm's joint order, stamped by the robot's clock (``robot_time_ns``);
- ``geometry_msgs/msg/PoseStamped``: the pose as recorded (header stamp);
- ``tf2_msgs/msg/TFMessage`` on ``/tf`` (with ``/tf_static``): the named frame (``--frame``) in its tree's root
  or in ``--base-frame``, composed through its parents (:func:`~lampskit.learn.bag_maths.compose_chain`).

Joint positions become the pad path by the arm's forward kinematics to the flange and the tool offset (default:
the described eraser's pad centre); a pose's frame is moved by the tool offset (default none). The demonstration
stays in the recording's frame (the robot base for joints), as the other readers do: learning fits the
demonstration's own surface frame (:mod:`lampskit.learn.learn`), so any fixed frame will do. Times are seconds
from the topic's first sample; ``--start`` / ``--end`` cut a window of them, then gaps are checked and a fast
state is thinned (:mod:`lampskit.learn.bag_maths`). Every refusal is one line naming what the recording holds.

The LBRState definition (both layouts the stack builds, FRI 1 and FRI 2) comes from the caller's arm
(:class:`ArmKinematics`): a bag that embeds its own definition (MCAP storage, and sqlite3 since ROS 2 Iron) is
decoded with that one.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lampskit.errors import DemoError
from lampskit.learn import bag_maths as bm
from lampskit.learn.demo import Demonstration

LBR_STATE = "lbr_fri_idl/msg/LBRState"
JOINT_STATE = "sensor_msgs/msg/JointState"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF = "tf2_msgs/msg/TFMessage"
#: The cell's robot state in its own recording (launch/record.py: JSON, schema ``lamps.<Type>``).
CELL_STATE = "lamps.RobotState"
#: Kinds a topic is looked for in, when none is given, in this order.
DEFAULT_KINDS = (LBR_STATE, JOINT_STATE, CELL_STATE, POSE_STAMPED)


@dataclass(frozen=True)
class ArmKinematics:
    """What the reader needs to know of the arm that was recorded.

    n_joints : number of joints; joint_index(name) : 0-based number of one of the arm's joint names, else None;
    joint_names : the valid names in words (for messages); flange_poses(q (T, n)) -> (p (T, 3) [m], R (T, 3, 3))
    of the flange in the base frame; tool_offset_m : the configured pad centre in the flange frame (3,) [m];
    msg_layouts : custom message type -> its ``.msg`` texts to try, in order, for a bag that embeds none.
    """

    n_joints: int
    joint_index: Callable[[str], int | None]
    joint_names: str
    flange_poses: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    tool_offset_m: tuple[float, float, float]
    msg_layouts: Mapping[str, tuple[str, ...]]


@dataclass(frozen=True)
class BagOptions:
    """Which path to take from a recording. Times [s] from the topic's first sample; offsets [m]."""

    topic: str | None = None
    frame: str | None = None
    base_frame: str | None = None
    tool_offset_m: tuple[float, float, float] | None = None
    start_s: float | None = None
    end_s: float | None = None
    max_gap_s: float | None = None


def is_recording(spec: str | Path) -> bool:
    """True for a rosbag2 folder (it has ``metadata.yaml``), an ``.mcap`` or a ``.db3`` file."""
    path = Path(spec)
    return (path / "metadata.yaml").is_file() if path.is_dir() else path.suffix.lower() in (".mcap", ".db3")


def read_recording_demo(spec: str | Path, arm: ArmKinematics, options: BagOptions = BagOptions()) -> Demonstration:
    """The pad path of one topic of a recording as a :class:`Demonstration` (see the module docstring)."""
    path = Path(spec)
    if not path.exists():
        raise DemoError(f"{path}: no such file or folder")
    source = _Json(path) if path.suffix.lower() == ".mcap" and _is_json_mcap(path) else _Ros(path, arm)
    topics = source.topics()
    try:
        topic = _choose_topic(topics, options)
    except DemoError as exc:
        raise DemoError(f"{path}: {exc}") from None
    kind = topics[topic][0]
    where = f"{path} {topic}"
    p: np.ndarray | None
    R: np.ndarray | None
    q: np.ndarray | None = None
    try:
        if kind == TF:
            t_ns, p, R = _tf_poses(source, topic, topics, options)
        elif kind == POSE_STAMPED:
            t_ns, p, R = _pose_track(source, topic)
        else:
            t_ns, q = _joint_track(source, topic, kind, arm)
            p = R = None
        keep = bm.increasing(t_ns)
        t_s = (t_ns[keep] - t_ns[keep[0]]) * 1e-9
        window = np.flatnonzero(bm.in_window(t_s, options.start_s, options.end_s))
        keep, t_s = keep[window], t_s[window]
        bm.check_gaps(t_s, options.max_gap_s if options.max_gap_s is not None else bm.gap_limit_s(t_s))
        sub = bm.thin(t_s)
        keep, t_s = keep[sub], t_s[sub]
        if p is None:
            assert q is not None  # a joint track
            p, R = arm.flange_poses(q[keep])
            offset = arm.tool_offset_m if options.tool_offset_m is None else options.tool_offset_m
        else:
            assert R is not None  # a pose track has both
            p, R = p[keep], R[keep]
            offset = options.tool_offset_m or (0.0, 0.0, 0.0)
        pad = bm.pad_from_frame(p, R, np.asarray(offset, float))
        quat = np.array([_quat_wxyz(r) for r in R])
        name = f"{path}:{topic}" + (f"#{options.frame}" if kind == TF else "")
        return Demonstration(t_s, pad, quat, source=name)
    except DemoError as exc:
        raise DemoError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------------------------- which topic


def _choose_topic(topics: dict[str, tuple[str, int]], options: BagOptions) -> str:
    listing = ", ".join(f"{t} ({k}, {n})" for t, (k, n) in sorted(topics.items())) or "no topics"
    topic = options.topic or ("/tf" if options.frame else None)
    if topic is None:
        for kind in DEFAULT_KINDS:
            found = sorted(t for t, (k, _) in topics.items() if k == kind)
            if len(found) == 1:
                topic = found[0]
                break
            if found:
                raise DemoError(f"several {kind} topics ({', '.join(found)}): choose one with --topic")
        if topic is None:
            raise DemoError(f"no robot state, joint state or pose topic in it (it has {listing}); "
                            "give --topic (and --frame for /tf)")
    if topic not in topics:
        raise DemoError(f"no topic {topic!r} in it; it has {listing}")
    kind, n = topics[topic]
    if kind not in (*DEFAULT_KINDS, TF):
        raise DemoError(f"{topic} carries {kind}; readable: {', '.join((*DEFAULT_KINDS, TF))}")
    if kind == TF and not options.frame:
        raise DemoError(f"{topic} carries transforms: name the frame to learn with --frame")
    if n == 0:
        raise DemoError(f"{topic} has no messages")
    return topic


# --------------------------------------------------------------------------------------------- tracks


def _stamp_ns(stamp) -> int:
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


def _stamps(stamps: list[int], logs: list[int]) -> np.ndarray:
    """The messages' own stamps, or the times they were logged when every own stamp is zero (a mock, a bad clock)."""
    own = np.asarray(stamps, dtype=np.int64)
    return own if own.any() else np.asarray(logs, dtype=np.int64)


def _joint_track(source, topic: str, kind: str, arm: ArmKinematics) -> tuple[np.ndarray, np.ndarray]:
    stamps, logs, rows = [], [], []
    cols: np.ndarray | None = None
    names: list[str] | None = None
    for log_ns, msg in source.messages([topic]):
        if kind == LBR_STATE:
            q, stamp = msg.measured_joint_position, int(msg.time_stamp_sec) * 10**9 + int(msg.time_stamp_nano_sec)
        elif kind == CELL_STATE:
            q, stamp = msg["q_rad"], int(msg.get("robot_time_ns") or msg.get("stamp_ns") or 0)
        else:
            msg_names = list(msg.name)
            if names != msg_names:
                names = msg_names
                cols = bm.joint_columns(names, arm.joint_index, arm.n_joints, arm.joint_names)
            if len(msg.position) != len(msg_names):
                raise DemoError(f"a message with {len(msg_names)} joint names but {len(msg.position)} positions")
            q, stamp = np.asarray(msg.position)[cols], _stamp_ns(msg.header.stamp)
        if len(q) != arm.n_joints:
            raise DemoError(f"{len(q)} joint positions in a message; the arm has {arm.n_joints}")
        rows.append(np.asarray(q, float))
        stamps.append(stamp)
        logs.append(log_ns)
    return _stamps(stamps, logs), np.array(rows)


def _pose_track(source, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    stamps, logs, p, q = [], [], [], []
    for log_ns, msg in source.messages([topic]):
        pose = msg.pose
        p.append((pose.position.x, pose.position.y, pose.position.z))
        q.append((pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w))
        stamps.append(_stamp_ns(msg.header.stamp))
        logs.append(log_ns)
    return _stamps(stamps, logs), np.array(p), bm.matrices_from_quat_xyzw(np.array(q))


def _tf_poses(source, topic: str, topics, options: BagOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The named frame's poses from ``topic`` (and ``/tf_static`` when the recording has it)."""
    per_child: dict[str, dict[str, Any]] = {}
    static_topics = {"/tf_static"} & set(topics)
    for log_ns, msg, static in ((t, m, topic_ in static_topics)
                                for topic_, t, m in source.messages_with_topic([topic, *static_topics])):
        for tr in msg.transforms:
            rec = per_child.setdefault(tr.child_frame_id, {"parent": tr.header.frame_id, "static": static,
                                                           "t": [], "log": [], "p": [], "q": []})
            tl, rot = tr.transform.translation, tr.transform.rotation
            rec["t"].append(_stamp_ns(tr.header.stamp))
            rec["log"].append(log_ns)
            rec["p"].append((tl.x, tl.y, tl.z))
            rec["q"].append((rot.x, rot.y, rot.z, rot.w))
    links = {}
    for child, rec in per_child.items():
        t_ns = _stamps(rec["t"], rec["log"])
        order = bm.increasing(t_ns)
        p, R = np.array(rec["p"])[order], bm.matrices_from_quat_xyzw(np.array(rec["q"])[order])
        if rec["static"]:
            links[child] = bm.FrameLink(rec["parent"], child, None, p[-1:], R[-1:])
        else:
            links[child] = bm.FrameLink(rec["parent"], child, t_ns[order], p, R)
    assert options.frame is not None, "a tf track without the frame to follow"  # the options' check refuses it
    return bm.compose_chain(bm.chain_to(options.frame, links, options.base_frame))


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    from lampskit.core.rotations import quat_wxyz_from_matrix

    return quat_wxyz_from_matrix(R)


# --------------------------------------------------------------------------------------------- the readers


class _Ros:
    """A rosbag2 folder, a ROS 2 MCAP file or a ``.db3`` through rosbags, decoded with one typestore."""

    def __init__(self, path: Path, arm: ArmKinematics) -> None:
        from rosbags.rosbag2 import Reader, ReaderError

        self.path, self.arm = path, arm
        try:
            with Reader(path) as reader:
                self.connections = list(reader.connections)
        except (ReaderError, OSError, ValueError, KeyError) as exc:
            raise DemoError(f"{path}: not a readable rosbag2 recording ({exc})") from None

    def topics(self) -> dict[str, tuple[str, int]]:
        out: dict[str, tuple[str, int]] = {}
        for c in self.connections:
            _, n = out.get(c.topic, (c.msgtype, 0))
            out[c.topic] = (c.msgtype, n + c.msgcount)
        return out

    def messages(self, topics: list[str]) -> Iterator[tuple[int, object]]:
        for _, log_ns, msg in self.messages_with_topic(topics):
            yield log_ns, msg

    def messages_with_topic(self, topics: list[str]) -> Iterator[tuple[str, int, object]]:
        from rosbags.rosbag2 import Reader

        conns_of = [c for c in self.connections if c.topic in topics]
        layout = 0
        store = self._typestore(conns_of, layout)
        with Reader(self.path) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for conn, log_ns, raw in reader.messages(connections=conns):
                while True:
                    try:
                        msg = store.deserialize_cdr(raw, conn.msgtype)
                        break
                    except Exception as exc:  # rosbags raises several types for bytes of another layout
                        layouts = self.arm.msg_layouts.get(conn.msgtype, ())
                        if conn.msgdef.data or layout + 1 >= len(layouts):
                            raise DemoError(f"a {conn.msgtype} message of {len(raw)} bytes does not decode "
                                            f"({type(exc).__name__})") from None
                        layout += 1
                        store = self._typestore(conns_of, layout)
                yield conn.topic, log_ns, msg

    def _typestore(self, conns, layout: int):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        store = get_typestore(Stores.ROS2_HUMBLE)
        for c in conns:
            if c.msgtype in store.types:
                continue
            if c.msgdef.data and c.msgdef.format.name == "MSG":
                types = get_types_from_msg(c.msgdef.data, c.msgtype)
            elif c.msgtype in self.arm.msg_layouts:
                types = get_types_from_msg(self.arm.msg_layouts[c.msgtype][layout], c.msgtype)
            else:
                raise DemoError(f"{c.topic} carries {c.msgtype}, whose definition is neither in the bag nor known")
            store.register({k: v for k, v in types.items() if k not in store.types})
        return store


def _is_json_mcap(path: Path) -> bool:
    """True for an MCAP file without CDR channels (the cell's own recording)."""
    summary = _mcap_summary(path)
    return not any(c.message_encoding == "cdr" for c in summary.channels.values())


def _mcap_summary(path: Path):
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, OSError, ValueError, EOFError) as exc:
        raise DemoError(f"{path}: not a readable MCAP file ({type(exc).__name__}: {exc})") from None
    if summary is None:
        raise DemoError(f"{path}: an MCAP file without a summary (cut short?); 'lamps report RUN_DIR' recovers "
                        "the cell's own recording")
    return summary


class _Json:
    """The cell's recording (:mod:`launch.record`): JSON messages, the schema name tells the kind."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.summary = _mcap_summary(path)

    def topics(self) -> dict[str, tuple[str, int]]:
        stats = self.summary.statistics
        counts = stats.channel_message_counts if stats else {}
        out = {}
        for cid, c in self.summary.channels.items():
            schema = self.summary.schemas.get(c.schema_id)
            out[c.topic] = (schema.name if schema else c.message_encoding, int(counts.get(cid, 0)))
        return out

    def messages(self, topics: list[str]) -> Iterator[tuple[int, dict]]:
        from mcap.reader import make_reader

        with open(self.path, "rb") as f:
            for _, _, message in make_reader(f).iter_messages(topics=topics):
                yield message.log_time, json.loads(message.data)
