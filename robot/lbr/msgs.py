"""lbr_fri_ros2_stack's messages on the wire: CDR through rosbags' typestore, keys as zenoh-bridge-ros2dds maps them.

The stack (ROS 2, ros2_control, FRI) publishes ``lbr_fri_idl/msg/LBRState``
on ``/<namespace>/state`` (its ``lbr_state_broadcaster``), the estimated
tool wrench as ``geometry_msgs/msg/WrenchStamped`` on
``/<namespace>/force_torque_broadcaster/wrench``, and its
``lbr_torque_command_controller`` takes ``lbr_fri_idl/msg/LBRTorqueCommand``
on ``/<namespace>/command/torque`` (namespace ``lbr`` by default).
zenoh-bridge-ros2dds maps the ROS topic ``/a/b`` to the Zenoh key ``a/b``
and forwards the DDS payload as it is: CDR with its 4-byte encapsulation
header. The message definitions below are the stack's (lbr_fri_idl 1.5),
registered from their ``.msg`` text; encoding and decoding are rosbags'.

FRI enumerations carried as ``int8`` in ``LBRState`` (KUKA::FRI, friClientIf.h):
:class:`SessionState`, :class:`SafetyState`, :class:`OperationMode`, :class:`DriveState`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from lampskit.errors import LampsError

N_JOINTS = 7
STATE_TYPE = "lbr_fri_idl/msg/LBRState"
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


#: KUKA::FRI::EClientCommandMode's value for torque overlay; EControlMode's for joint impedance.
CLIENT_COMMAND_MODE_TORQUE = 3
CONTROL_MODE_JOINT_IMPEDANCE = 2


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
    q_commanded_rad: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))


def _typestore():
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    types.update(get_types_from_msg(LBR_STATE_MSG, STATE_TYPE))
    types.update(get_types_from_msg(LBR_TORQUE_COMMAND_MSG, TORQUE_COMMAND_TYPE))
    store.register(types)
    return store


TYPESTORE = _typestore()
_State = TYPESTORE.types[STATE_TYPE]
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


def decode_state(raw: bytes) -> LbrState:
    """An ``LBRState`` from its CDR bytes; LbrWireError for bad bytes, wrong lengths or non-finite values."""
    m = _decode(raw, STATE_TYPE)
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
        q_commanded_rad=_vector("commanded_joint_position", m.commanded_joint_position))


def encode_state(s: LbrState, *, connection_quality: int = 3, overlay_type: int = 1,
                 commanded_torque_nm: np.ndarray | None = None, tracking_performance: float = 1.0) -> bytes:
    """The CDR bytes of an ``LBRState`` (what the stack publishes; the lbr peer uses it)."""
    zeros = np.zeros(N_JOINTS)
    msg = _State(
        sample_time=float(s.sample_time_s), session_state=int(s.session_state),
        connection_quality=int(connection_quality), safety_state=int(s.safety_state),
        operation_mode=int(s.operation_mode), drive_state=int(s.drive_state),
        client_command_mode=int(s.client_command_mode), overlay_type=int(overlay_type),
        control_mode=int(s.control_mode), time_stamp_sec=int(s.stamp_ns // 1_000_000_000),
        time_stamp_nano_sec=int(s.stamp_ns % 1_000_000_000),
        measured_joint_position=np.asarray(s.q_rad, float),
        commanded_joint_position=np.asarray(s.q_commanded_rad, float),
        measured_torque=np.asarray(s.tau_measured_nm, float),
        commanded_torque=np.asarray(zeros if commanded_torque_nm is None else commanded_torque_nm, float),
        external_torque=np.asarray(s.tau_external_nm, float), ipo_joint_position=np.asarray(s.q_rad, float),
        tracking_performance=float(tracking_performance))
    return bytes(TYPESTORE.serialize_cdr(msg, STATE_TYPE))


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
