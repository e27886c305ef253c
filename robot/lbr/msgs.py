"""lbr_fri_ros2_stack's messages on the wire: CDR through rosbags' typestore, keys as zenoh-bridge-ros2dds maps them.

The stack (ROS 2, ros2_control, FRI) publishes ``lbr_fri_idl/msg/LBRState``
on ``/<namespace>/state`` (its ``lbr_state_broadcaster``), the estimated
tool wrench as ``geometry_msgs/msg/WrenchStamped`` on
``/<namespace>/force_torque_broadcaster/wrench``, and its
``lbr_torque_command_controller`` takes ``lbr_fri_idl/msg/LBRTorqueCommand``
on ``/<namespace>/command/torque`` (namespace ``lbr`` by default).
zenoh-bridge-ros2dds maps the ROS topic ``/a/b`` to the Zenoh key ``a/b``
and forwards the DDS payload as it is: CDR with its 4-byte encapsulation
header. The message definitions below are the stack's (lbr-stack/lbr_fri_idl,
``msg/LBRState.msg`` on its ``fri-1`` branch, e422bff, and its ``fri-2``
branch, a54bc11, which drops ``commanded_joint_position``: the stack builds
against the FRI client SDK of the robot, 1.x or 2.x), registered from
their ``.msg`` text; encoding and decoding are rosbags'. Both layouts are
fixed-size, so the number of bytes tells them apart (:func:`state_layout`).

FRI enumerations carried as ``int8`` in ``LBRState`` (KUKA::FRI, friClientIf.h):
:class:`SessionState`, :class:`ConnectionQuality`, :class:`SafetyState`, :class:`OperationMode`,
:class:`DriveState`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from lampskit.errors import LampsError

N_JOINTS = 7
STATE_TYPE = "lbr_fri_idl/msg/LBRState"
#: The FRI 2 layout of the same message, registered under its own name (one typestore holds both).
STATE_TYPE_FRI2 = "lbr_fri_idl_fri2/msg/LBRState"
TORQUE_COMMAND_TYPE = "lbr_fri_idl/msg/LBRTorqueCommand"
WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"

#: lbr_fri_idl/msg/LBRState.msg (field order and types as the stack defines them).
LBR_STATE_MSG = """
float64 sample_time
int8 session_state
int8 connection_quality
int8 safety_state
int8 operation_mode
int8 drive_state
int8 client_command_mode
int8 overlay_type
int8 control_mode
uint32 time_stamp_sec
uint32 time_stamp_nano_sec
float64[7] measured_joint_position
float64[7] commanded_joint_position
float64[7] measured_torque
float64[7] commanded_torque
float64[7] external_torque
float64[7] ipo_joint_position
float64 tracking_performance
"""

#: lbr_fri_idl/msg/LBRState.msg on the ``fri-2`` branch (FRI 2.x): no ``commanded_joint_position``.
LBR_STATE_MSG_FRI2 = "\n".join(line for line in LBR_STATE_MSG.splitlines()
                               if not line.startswith("float64[7] commanded_joint_position"))

#: lbr_fri_idl/msg/LBRTorqueCommand.msg: joint position and torque overlay.
LBR_TORQUE_COMMAND_MSG = """
float64[7] joint_position
float64[7] torque
"""


class SessionState(IntEnum):
    """KUKA::FRI::ESessionState."""

    IDLE = 0
    MONITORING_WAIT = 1
    MONITORING_READY = 2
    COMMANDING_WAIT = 3
    COMMANDING_ACTIVE = 4


class ConnectionQuality(IntEnum):
    """KUKA::FRI::EConnectionQuality (lbr-stack/fri ``ros2-fri-1.15`` friClientIf.h:80-86): FAIR is "insufficient for
    command mode", GOOD "sufficient"; the stack copies it into every state (state.cpp:15)."""

    POOR = 0
    FAIR = 1
    GOOD = 2
    EXCELLENT = 3


class SafetyState(IntEnum):
    """KUKA::FRI::ESafetyState."""

    NORMAL_OPERATION = 0
    SAFETY_STOP_LEVEL_0 = 1
    SAFETY_STOP_LEVEL_1 = 2
    SAFETY_STOP_LEVEL_2 = 3


class OperationMode(IntEnum):
    """KUKA::FRI::EOperationMode (T1 is manual reduced velocity)."""

    TEST_MODE_1 = 0
    TEST_MODE_2 = 1
    AUTOMATIC_MODE = 2


class DriveState(IntEnum):
    """KUKA::FRI::EDriveState."""

    OFF = 0
    TRANSITIONING = 1
    ACTIVE = 2


class ClientCommandMode(IntEnum):
    """KUKA::FRI::EClientCommandMode (FRI 2 names POSITION ``JOINT_POSITION`` and adds CARTESIAN_POSE = 4)."""

    NO_COMMAND_MODE = 0
    POSITION = 1
    WRENCH = 2
    TORQUE = 3
    CARTESIAN_POSE = 4


class ControlMode(IntEnum):
    """KUKA::FRI::EControlMode: the robot-side controller the LBRServer app runs."""

    POSITION_CONTROL_MODE = 0
    CART_IMP_CONTROL_MODE = 1
    JOINT_IMP_CONTROL_MODE = 2
    NO_CONTROL = 3


#: KUKA::FRI::EClientCommandMode's value for torque overlay; EControlMode's for joint impedance.
CLIENT_COMMAND_MODE_TORQUE = int(ClientCommandMode.TORQUE)
CONTROL_MODE_JOINT_IMPEDANCE = int(ControlMode.JOINT_IMP_CONTROL_MODE)
#: The FRI client SDK major versions the stack builds against (lbr_fri_idl branches ``fri-1`` and ``fri-2``).
FRI_MAJORS = (1, 2)


def enum_name(enum, value: int | None) -> str:
    """The name of ``value`` in the FRI enumeration ``enum``; ``unknown(v)`` for another number, ``none`` for None."""
    if value is None:
        return "none"
    try:
        return enum(value).name
    except ValueError:
        return f"unknown({value})"


def stack_joint_names(branch: str, robot_name: str = "lbr") -> tuple[str, ...]:
    """The stack's joint names in A1..A7 order: ``<robot_name>_A1`` .. on ``rolling`` / ``jazzy``, ``A1`` ..
    on ``humble`` (the branch's ros2_control xacro and its torque command controller name them so)."""
    if branch == "humble":
        return tuple(f"A{i}" for i in range(1, N_JOINTS + 1))
    return tuple(f"{robot_name}_A{i}" for i in range(1, N_JOINTS + 1))


class LbrWireError(LampsError, ValueError):
    """Bytes on a bridge key that are not the expected CDR message, or one with unusable values."""


@dataclass(frozen=True)
class LbrTopics:
    """Where the stack's topics appear as Zenoh keys (zenoh-bridge-ros2dds: ``/a/b`` -> ``a/b``).

    namespace : the robot name the stack runs under (``lbr``); the rest are the
    topics relative to it, as the stack names them.
    """

    namespace: str = "lbr"
    state: str = "state"
    torque_command: str = "command/torque"
    wrench: str = "force_torque_broadcaster/wrench"
    joint_states: str = "joint_states"

    def key(self, topic: str) -> str:
        ns = self.namespace.strip("/")
        return f"{ns}/{topic.strip('/')}" if ns else topic.strip("/")


@dataclass
class LbrState:
    """One decoded ``LBRState`` with the fields we use (SI units, joints A1..A7)."""

    sample_time_s: float
    session_state: int
    safety_state: int
    operation_mode: int
    drive_state: int
    client_command_mode: int
    control_mode: int
    stamp_ns: int
    q_rad: np.ndarray
    tau_measured_nm: np.ndarray
    tau_external_nm: np.ndarray
    q_commanded_rad: np.ndarray | None = field(default_factory=lambda: np.zeros(N_JOINTS))
    """The robot's commanded joint position (FRI 1 only; None in an FRI 2 state)."""
    tau_commanded_nm: np.ndarray | None = None
    """The robot's "last commanded joint torques" (``commanded_torque``, friLBRState.h:204-209); None: not known."""
    connection_quality: int = int(ConnectionQuality.EXCELLENT)
    """The FRI connection quality the robot reports (:class:`ConnectionQuality`)."""


def _typestore():
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    types.update(get_types_from_msg(LBR_STATE_MSG, STATE_TYPE))
    types.update(get_types_from_msg(LBR_TORQUE_COMMAND_MSG, TORQUE_COMMAND_TYPE))
    types.update(get_types_from_msg(LBR_STATE_MSG_FRI2, STATE_TYPE_FRI2))
    store.register(types)
    return store


TYPESTORE = _typestore()
_State = TYPESTORE.types[STATE_TYPE]
_State2 = TYPESTORE.types[STATE_TYPE_FRI2]
_STATE_TYPES = {1: STATE_TYPE, 2: STATE_TYPE_FRI2}
_Torque = TYPESTORE.types[TORQUE_COMMAND_TYPE]


def _decode(raw: bytes, typename: str):
    try:
        return TYPESTORE.deserialize_cdr(raw, typename)
    except Exception as exc:  # rosbags raises several types for truncated or foreign bytes
        raise LbrWireError(f"not a valid CDR {typename} ({len(raw)} bytes): {type(exc).__name__}") from None


def _vector(name: str, values, n: int = N_JOINTS) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if v.shape != (n,):
        raise LbrWireError(f"{name} must hold {n} values, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise LbrWireError(f"{name} holds NaN or inf")
    return v


def state_size(fri_major: int) -> int:
    """Bytes of a CDR ``LBRState`` of the FRI ``fri_major`` layout (header included; both are fixed-size)."""
    return _STATE_SIZES[fri_major]


def state_layout(raw: bytes) -> int | None:
    """The FRI major version whose ``LBRState`` is ``len(raw)`` bytes, or None when neither is."""
    for major, size in _STATE_SIZES.items():
        if len(raw) == size:
            return major
    return None


def decode_state(raw: bytes, fri_major: int = 1) -> LbrState:
    """An ``LBRState`` of the FRI ``fri_major`` layout from its CDR bytes.

    LbrWireError for bad bytes, the other layout (named), wrong lengths or non-finite values.
    """
    if len(raw) != _STATE_SIZES[fri_major]:
        other = state_layout(raw)
        if other is not None:
            raise LbrWireError(f"an FRI {other} LBRState ({len(raw)} bytes), but the adapter expects FRI "
                               f"{fri_major} ({_STATE_SIZES[fri_major]} bytes): set [lbr] fri_major = {other}")
    m = _decode(raw, _STATE_TYPES[fri_major])
    if not np.isfinite(m.sample_time) or m.sample_time <= 0:
        raise LbrWireError(f"sample_time must be finite and > 0 s, got {m.sample_time!r}")
    return LbrState(
        sample_time_s=float(m.sample_time), session_state=int(m.session_state), safety_state=int(m.safety_state),
        operation_mode=int(m.operation_mode), drive_state=int(m.drive_state),
        client_command_mode=int(m.client_command_mode), control_mode=int(m.control_mode),
        stamp_ns=int(m.time_stamp_sec) * 1_000_000_000 + int(m.time_stamp_nano_sec),
        q_rad=_vector("measured_joint_position", m.measured_joint_position),
        tau_measured_nm=_vector("measured_torque", m.measured_torque),
        tau_external_nm=_vector("external_torque", m.external_torque),
        q_commanded_rad=(_vector("commanded_joint_position", m.commanded_joint_position) if fri_major == 1
                         else None),
        tau_commanded_nm=_vector("commanded_torque", m.commanded_torque),
        connection_quality=int(m.connection_quality))


def encode_state(s: LbrState, *, connection_quality: int | None = None, overlay_type: int = 1,
                 commanded_torque_nm: np.ndarray | None = None, tracking_performance: float = 1.0,
                 fri_major: int = 1, ipo_joint_position_rad: np.ndarray | None = None) -> bytes:
    """The CDR bytes of an ``LBRState`` of the FRI ``fri_major`` layout (what the stack publishes); the connection
    quality is the state's unless given."""
    zeros = np.zeros(N_JOINTS)
    fields = dict(
        sample_time=float(s.sample_time_s), session_state=int(s.session_state),
        connection_quality=int(s.connection_quality if connection_quality is None else connection_quality),
        safety_state=int(s.safety_state),
        operation_mode=int(s.operation_mode), drive_state=int(s.drive_state),
        client_command_mode=int(s.client_command_mode), overlay_type=int(overlay_type),
        control_mode=int(s.control_mode), time_stamp_sec=int(s.stamp_ns // 1_000_000_000),
        time_stamp_nano_sec=int(s.stamp_ns % 1_000_000_000),
        measured_joint_position=np.asarray(s.q_rad, float),
        measured_torque=np.asarray(s.tau_measured_nm, float),
        commanded_torque=np.asarray(commanded_torque_nm if commanded_torque_nm is not None else
                                    s.tau_commanded_nm if s.tau_commanded_nm is not None else zeros, float),
        external_torque=np.asarray(s.tau_external_nm, float),
        ipo_joint_position=np.asarray(s.q_rad if ipo_joint_position_rad is None else ipo_joint_position_rad, float),
        tracking_performance=float(tracking_performance))
    if fri_major == 1:
        q_cmd = s.q_commanded_rad if s.q_commanded_rad is not None else s.q_rad
        return bytes(TYPESTORE.serialize_cdr(_State(**fields, commanded_joint_position=np.asarray(q_cmd, float)),
                                             STATE_TYPE))
    return bytes(TYPESTORE.serialize_cdr(_State2(**fields), STATE_TYPE_FRI2))


_STATE_SIZES = {major: len(encode_state(LbrState(0.001, 0, 0, 0, 0, 0, 0, 0, np.zeros(N_JOINTS), np.zeros(N_JOINTS),
                                                   np.zeros(N_JOINTS)), fri_major=major)) for major in FRI_MAJORS}


def encode_torque_command(joint_position_rad: np.ndarray, torque_nm: np.ndarray) -> bytes:
    """The CDR bytes of an ``LBRTorqueCommand`` (joint position (7,) [rad] and torque overlay (7,) [Nm])."""
    msg = _Torque(joint_position=np.asarray(joint_position_rad, float), torque=np.asarray(torque_nm, float))
    return bytes(TYPESTORE.serialize_cdr(msg, TORQUE_COMMAND_TYPE))


def decode_torque_command(raw: bytes) -> tuple[np.ndarray, np.ndarray]:
    """(joint_position (7,) [rad], torque (7,) [Nm]) of an ``LBRTorqueCommand``; LbrWireError when unusable."""
    m = _decode(raw, TORQUE_COMMAND_TYPE)
    return _vector("joint_position", m.joint_position), _vector("torque", m.torque)


def decode_wrench(raw: bytes) -> tuple[str, np.ndarray]:
    """(frame_id, (6,) force [N] then torque [Nm]) of a ``WrenchStamped``; LbrWireError when unusable."""
    m = _decode(raw, WRENCH_TYPE)
    w = m.wrench
    return m.header.frame_id, _vector("wrench", [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y,
                                                 w.torque.z], 6)


def encode_wrench(frame_id: str, wrench: np.ndarray, stamp_ns: int = 0) -> bytes:
    """The CDR bytes of a ``WrenchStamped`` (force [N] then torque [Nm])."""
    T = TYPESTORE.types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000),
                                                                            nanosec=int(stamp_ns % 1_000_000_000)),
                                      frame_id=frame_id)
    v3 = T["geometry_msgs/msg/Vector3"]
    w = np.asarray(wrench, float)
    msg = T[WRENCH_TYPE](header=header, wrench=T["geometry_msgs/msg/Wrench"](force=v3(x=w[0], y=w[1], z=w[2]),
                                                                            torque=v3(x=w[3], y=w[4], z=w[5])))
    return bytes(TYPESTORE.serialize_cdr(msg, WRENCH_TYPE))


def decode_joint_names(raw: bytes) -> tuple[str, ...]:
    """The joint names of a ``sensor_msgs/JointState``; LbrWireError when the bytes are not one."""
    return tuple(_decode(raw, JOINT_STATE_TYPE).name)


def encode_joint_state(names, q_rad: np.ndarray, stamp_ns: int = 0) -> bytes:
    """The CDR bytes of a ``sensor_msgs/JointState`` with positions only."""
    T = TYPESTORE.types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000),
                                                                            nanosec=int(stamp_ns % 1_000_000_000)),
                                      frame_id="")
    msg = T[JOINT_STATE_TYPE](header=header, name=list(names), position=np.asarray(q_rad, float),
                              velocity=np.zeros(0), effort=np.zeros(0))
    return bytes(TYPESTORE.serialize_cdr(msg, JOINT_STATE_TYPE))
