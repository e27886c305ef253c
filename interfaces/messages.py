"""Typed messages of the LAMPS cell (msgspec Structs, msgpack on the wire).

Every message carries ``version`` (:data:`SCHEMA_VERSION`) and a type tag, so a payload of the wrong type or
version is rejected on decode (:func:`interfaces.codec.decode`), never misread. Structs are encoded as msgpack
arrays (``array_like``): compact, and floats are IEEE doubles, so float vectors round-trip bit-exactly.
``__post_init__`` checks what the types cannot (vector lengths, finiteness, ranges), on decode too. The string
and counter bounds and the shared checks are in :mod:`interfaces.message_checks`.

Units are SI; stamps are ``time.monotonic_ns()`` of the sender (``stamp_ns``) plus ``time.time_ns()``
(``wall_ns``) where logs need it. Poses are ``position_m`` (3,) in the parent frame and ``quat_wxyz`` (4,), scalar
first (PyBullet's scalar-last order is converted at the sim's edge).
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated

import msgspec
from msgspec.structs import force_setattr

from interfaces.arm_estimate import ArmEstimate
from interfaces.message_checks import (DETAIL_MAX, NAME_MAX, TEXT_MAX, Certificate, Counters, Detail, Mac, Name, Nonce,
                                       Signature, Text, bounded_counters, check_finite, check_same_length, clip_strings)

#: Bump when a change could make an old reader misread a new message.
SCHEMA_VERSION = 2

#: Commands the robot side understands.
#: TorqueCommand modes: apply the torques, or brake and hold position (torques ignored).
TORQUE, HOLD = "torque", "hold"
COMMAND_MODES = (TORQUE, HOLD)
#: Image encodings a CameraFrame may carry.
ENCODINGS = ("rgb8", "bgr8", "mono8", "jpeg", "png")
#: How perception knows the board in a :class:`Stains` message.
BOARD_STATES = ("seen", "held", "lost")
_BYTES_PER_PIXEL = {"rgb8": 3, "bgr8": 3, "mono8": 1}


class Phase(StrEnum):
    """The controller's phases, in the order of their trace codes; each equals its name as a string (the wire format).

    INIT -> WAIT_PEERS -> APPROACH -> TRANSITION -> WIPE -> ... -> RETREAT
    -> DONE; PAUSED, FAULT and ESTOP are reachable from any phase
    (:mod:`controller.executor`). TEACH: the arm is hand-guided (``lamps
    teach``, :mod:`controller.teach`), no skill runs.
    """

    INIT = "INIT"
    WAIT_PEERS = "WAIT_PEERS"
    APPROACH = "APPROACH"
    WIPE = "WIPE"
    TRANSITION = "TRANSITION"
    RETREAT = "RETREAT"
    DONE = "DONE"
    PAUSED = "PAUSED"
    FAULT = "FAULT"
    ESTOP = "ESTOP"
    TEACH = "TEACH"


#: The phases' names, as :class:`ControllerStatus` carries them.
PHASES = tuple(p.value for p in Phase)


class Message(msgspec.Struct, frozen=True, kw_only=True, array_like=True, tag=True):
    """Base of every message. Wire layout: ``[type tag, fields..., version]``."""

    version: int = SCHEMA_VERSION


class Pose(msgspec.Struct, frozen=True, array_like=True):
    """A frame in its parent: ``position_m`` (3,) [m], ``quat_wxyz`` (4,), unit norm."""

    position_m: list[float]
    quat_wxyz: list[float]

    def __post_init__(self) -> None:
        check_finite("position_m", self.position_m, 3)
        check_finite("quat_wxyz", self.quat_wxyz, 4)
        norm = math.sqrt(sum(q * q for q in self.quat_wxyz))
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"quat_wxyz must have unit norm, got {norm:.9g}")


class Capabilities(msgspec.Struct, frozen=True, array_like=True):
    """What the robot side does by itself.

    gravity_compensated : the robot adds gravity torques itself (the real iiwa
    does); the controller must not add them again. torque_limits_nm : (n,)
    absolute joint torque limits [Nm]. backend : ``"sim"``, ``"lbr"``, ... (for
    logs only; controllers must not branch on it). state_rate_hz : how often
    the robot samples and publishes its state [Hz] (the FRI rate; 0 = not
    declared): a real-time controller faster than it only answers the same
    state again.
    """

    gravity_compensated: bool
    torque_limits_nm: list[float]
    backend: Name = "sim"
    state_rate_hz: float = 0.0

    def __post_init__(self) -> None:
        check_finite("torque_limits_nm", self.torque_limits_nm)
        if any(v <= 0 for v in self.torque_limits_nm):
            raise ValueError("torque_limits_nm must be positive")
        check_finite("state_rate_hz", [self.state_rate_hz])
        if self.state_rate_hz < 0:
            raise ValueError("state_rate_hz must be >= 0 (0: not declared)")


class RobotState(Message, frozen=True):
    """Robot side -> controller, every step.

    q_rad, dq_rad_s, tau_nm : (n,) joint positions [rad], velocities [rad/s],
    applied joint torques [Nm] (everything the joints exert, including the
    robot's own gravity compensation when it has one). wrench_world : (6,)
    contact force [N] then torque [Nm] about the pad centre (TCP) that the
    board exerts on the eraser, world axes. ``seq`` counts steps;
    ``robot_time_ns`` is the robot side's own clock (simulated time in the
    sim), which a lock-step controller uses as its time base.
    ``command_seq`` is the ``seq`` of the command the robot applied over the
    cycle that ended in this state, -1 when it applied none of the
    controller's (it held, braked, or was e-stopped): what lets the
    controller check that the arm moved as it was told. ``estop``: the
    robot side's own e-stop is engaged (it holds whatever is commanded until
    the operator's release reaches it); the controller keeps its phase in
    ESTOP while it is, so the two agree. ``held_cycles`` counts the cycles
    the robot side has held since it started (each state with
    ``command_seq`` -1, once): a controller that answers only the newest
    state still learns of a hold in the states it skipped.
    """

    seq: int
    stamp_ns: int
    q_rad: list[float]
    dq_rad_s: list[float]
    tau_nm: list[float]
    wrench_world: list[float]
    capabilities: Capabilities
    robot_time_ns: int = 0
    wall_ns: int = 0
    command_seq: int = -1
    estop: bool = False
    held_cycles: int = 0

    def __post_init__(self) -> None:
        names = ("q_rad", "dq_rad_s", "tau_nm")
        vectors = (self.q_rad, self.dq_rad_s, self.tau_nm)
        check_same_length(names, vectors)
        for name, v in zip(names, vectors):
            check_finite(name, v)
        check_finite("wrench_world", self.wrench_world, 6)
        if len(self.capabilities.torque_limits_nm) != len(self.q_rad):
            raise ValueError("capabilities.torque_limits_nm must have one entry per joint")
        if self.seq < 0:
            raise ValueError(f"seq must be >= 0, got {self.seq}")
        if self.held_cycles < 0:
            raise ValueError(f"held_cycles must be >= 0, got {self.held_cycles}")


class TorqueCommand(Message, frozen=True):
    """Controller -> robot side, answering state ``seq``.

    tau_nm : (n,) joint torques [Nm] (without gravity when the robot
    compensates it). mode ``"hold"``: brake and hold position, torques ignored.
    ``session``: the sending controller's session (its Zenoh id); the robot
    side serves one controller session at a time. ``mac``: the command's
    authentication under the key the controller and the robot side share
    (:mod:`interfaces.arm_auth`; empty in a cell without identities).
    """

    seq: int
    stamp_ns: int
    tau_nm: list[float]
    mode: Name = "torque"
    session: Name = ""
    mac: Mac = b""

    def __post_init__(self) -> None:
        check_finite("tau_nm", self.tau_nm)
        if self.mode not in COMMAND_MODES:
            raise ValueError(f"mode must be one of {COMMAND_MODES}, got {self.mode!r}")


class CameraIntrinsics(msgspec.Struct, frozen=True, array_like=True):
    """Pinhole intrinsics [px]: focal lengths, principal point, image size; no distortion."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        check_finite("intrinsics", (self.fx, self.fy, self.cx, self.cy))
        if self.fx <= 0 or self.fy <= 0 or self.width <= 0 or self.height <= 0:
            raise ValueError("focal lengths and image size must be positive")


class CameraFrame(Message, frozen=True):
    """A camera image with what is needed to use it.

    data : raw pixels row-major (``rgb8``/``bgr8``/``mono8``, size
    width * height * channels) or a compressed image (``jpeg``/``png``).
    T_camera_to_world : camera pose (optical frame: x right, y down, z forward).
    robot_time_ns : the robot side's clock at the moment shown (sim time for
    simulated frames, 0 when unknown). seq : counts this camera's frames
    (a gap is frames a consumer did not get).
    """

    seq: int
    stamp_ns: int
    camera: Name
    encoding: Name
    data: bytes
    intrinsics: CameraIntrinsics
    T_camera_to_world: Pose
    robot_time_ns: int = 0

    def __post_init__(self) -> None:
        if self.encoding not in ENCODINGS:
            raise ValueError(f"encoding must be one of {ENCODINGS}, got {self.encoding!r}")
        per_px = _BYTES_PER_PIXEL.get(self.encoding)
        size = self.intrinsics.width * self.intrinsics.height * (per_px or 0)
        if per_px is not None and len(self.data) != size:
            raise ValueError(f"{self.encoding} image of {self.intrinsics.width}x{self.intrinsics.height} "
                             f"needs {size} bytes, got {len(self.data)}")


class StainObservation(msgspec.Struct, frozen=True, array_like=True):
    """One stain as perception sees it.

    centre_board_m (2,) in the board frame; centre_world_m (3,) in the world
    (robot base) frame; size_m: larger extent [m]; extent_board_m (2,) along
    board x and y [m]; remaining: dirt left relative to the first sighting,
    visible: fraction of the stain not occluded, both in [0, 1]; kappa:
    wiping of this stain is complete. Optional (older senders leave them
    out): width_m across the main axis [m] (0: not known), axis_board_rad
    the main axis from board x [rad]; the ink that remains of the stain
    (what wiping has not lifted yet, hidden parts as last seen):
    ink_centre_board_m (2,) (empty: none left or not known), ink_size_m,
    ink_width_m [m], ink_axis_board_rad [rad]; colour: the name of the
    stain's ink in perception's palette (``[perception.ink] inks``; empty:
    not known); smeared: perception saw ``passes`` passes over the stain
    (hidden, then back in view) and the last ``[perception.smear] passes``
    of them lowered its remaining by less than ``min_progress``: wiping no
    longer cleans it (:mod:`perception.smear`).
    """

    id: int
    centre_board_m: list[float]
    centre_world_m: list[float]
    size_m: float
    extent_board_m: list[float]
    remaining: float
    visible: float
    kappa: bool
    width_m: float = 0.0
    axis_board_rad: float = 0.0
    ink_centre_board_m: list[float] = msgspec.field(default_factory=list)
    ink_size_m: float = 0.0
    ink_width_m: float = 0.0
    ink_axis_board_rad: float = 0.0
    colour: str = ""
    smeared: bool = False
    passes: int = 0

    def __post_init__(self) -> None:
        check_finite("centre_board_m", self.centre_board_m, 2)
        check_finite("centre_world_m", self.centre_world_m, 3)
        check_finite("extent_board_m", self.extent_board_m, 2)
        check_finite("size_m", (self.size_m,))
        if not isinstance(self.colour, str) or len(self.colour) > 16:
            raise ValueError(f"colour must be an ink name of at most 16 characters, got {self.colour!r}")
        if self.size_m <= 0 or self.passes < 0:
            raise ValueError(f"size_m must be positive and passes >= 0, got {self.size_m}, {self.passes}")
        check_finite("width_m, axis_board_rad, ink_size_m, ink_width_m, ink_axis_board_rad",
                (self.width_m, self.axis_board_rad, self.ink_size_m, self.ink_width_m, self.ink_axis_board_rad))
        if self.width_m < 0 or self.ink_width_m < 0 or self.ink_size_m < 0:
            raise ValueError(f"widths and ink_size_m must be >= 0, got {self.width_m}, {self.ink_width_m}, "
                             f"{self.ink_size_m}")
        if self.ink_centre_board_m:
            check_finite("ink_centre_board_m", self.ink_centre_board_m, 2)
            if self.ink_size_m <= 0:
                raise ValueError("ink_size_m must be positive when ink_centre_board_m is given")
        for name, v in (("remaining", self.remaining), ("visible", self.visible)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v!r}")


class Stains(Message, frozen=True):
    """Perception -> controller: the board and its stains.

    T_board_to_world : board frame (origin at a corner, x along the width, y
    along the height, z out of the board). board_size_m : (2,) width, height.
    board : ``"seen"`` (markers found in this frame), ``"held"`` (the last
    good pose, markers hidden for a moment) or ``"lost"``: nothing is known
    now, every stain has ``visible = 0`` and ``kappa = False`` and a consumer
    must not act on the stains. frame_seq / robot_time_ns : the camera frame
    the stains come from (robot_time_ns 0 when unknown). camera_world_m :
    (3,) the camera's position in the world [m] (empty: not known).
    """

    seq: int
    stamp_ns: int
    T_board_to_world: Pose
    board_size_m: list[float]
    stains: list[StainObservation]
    board: Name = "seen"
    frame_seq: int = -1
    robot_time_ns: int = 0
    camera_world_m: list[float] = msgspec.field(default_factory=list)

    def __post_init__(self) -> None:
        check_finite("board_size_m", self.board_size_m, 2)
        if self.camera_world_m:
            check_finite("camera_world_m", self.camera_world_m, 3)
        if self.board not in BOARD_STATES:
            raise ValueError(f"board must be one of {BOARD_STATES}, got {self.board!r}")
        ids = [s.id for s in self.stains]
        if len(set(ids)) != len(ids):
            raise ValueError(f"stain ids must be unique, got {ids}")


class LoopTiming(msgspec.Struct, frozen=True, array_like=True):
    """Statistics of a fixed-rate loop over its last window [us]; counters since start."""

    period_p50_us: float = 0.0
    period_p99_us: float = 0.0
    period_max_us: float = 0.0
    read_p99_us: float = 0.0
    update_p99_us: float = 0.0
    write_p99_us: float = 0.0
    ticks: int = 0
    overruns: int = 0


class ControllerStatus(Message, frozen=True):
    """Controller -> anyone: phase, what runs, force, timing, counters and what it estimated of the arm.

    phase : a :class:`Phase` name; reason : why (always set in PAUSED, FAULT, ESTOP); current_mp : e.g.
    ``"periodic 3"``; normal_force_n : measured contact force along the board normal [N]; counters : e.g. dropped
    samples per key; robot_time_ns : the controller's time on the robot's clock (the sum of its ticks' steps since
    it started) [ns], 0 before the first state; arm : the flange load and model error (:class:`ArmEstimate`).
    """

    seq: int
    stamp_ns: int
    phase: Name
    reason: Text = ""
    current_mp: Text = ""
    stain_id: int = -1
    normal_force_n: float = 0.0
    timing: LoopTiming = msgspec.field(default_factory=LoopTiming)
    counters: Counters = msgspec.field(default_factory=dict)
    wall_ns: int = 0
    robot_time_ns: int = 0
    #: how the controller joined (``mtls+acl as controller``, or ``INSECURE: ...``), set by its node on publishing
    security: Name = ""
    arm: ArmEstimate = msgspec.field(default_factory=ArmEstimate)

    def __post_init__(self) -> None:
        clip_strings(self, reason=TEXT_MAX, current_mp=TEXT_MAX)
        force_setattr(self, "counters", bounded_counters(self.counters))
        if self.phase not in PHASES:
            raise ValueError(f"phase must be one of {', '.join(PHASES)}, got {self.phase!r}")


class ControllerTrace(Message, frozen=True):
    """Controller -> recorders: every control tick since the previous batch, reference and measurement.

    columns : names of the ``c`` columns (``controller.core.TRACE_COLUMNS``:
    time [s], phase code, board-frame reference xy / velocity / acceleration,
    measured pad position, world positions [m], forces [N], contact flag).
    data : ``n_rows * c`` float64 little-endian, row-major. first_tick : the
    controller tick of the first row; dropped : rows lost before this batch
    (the ring was too short for the publishing period).
    """

    seq: int
    stamp_ns: int
    columns: Annotated[list[Name], msgspec.Meta(max_length=64)]
    first_tick: int
    n_rows: int
    data: bytes
    dropped: int = 0

    def __post_init__(self) -> None:
        if self.n_rows < 0 or len(self.data) != 8 * self.n_rows * len(self.columns):
            raise ValueError(f"trace data holds {len(self.data)} bytes, not {self.n_rows} rows of "
                             f"{len(self.columns)} float64")


class ServiceStatus(Message, frozen=True):
    """A service's health: what it processed, dropped and why (counters by reason), its loop timing."""

    service: Name
    seq: int
    stamp_ns: int
    counters: Counters = msgspec.field(default_factory=dict)
    detail: Detail = ""
    timing: LoopTiming = msgspec.field(default_factory=LoopTiming)
    #: how the service joined (``mtls+acl as robot``, or ``INSECURE: ...``), set by its node on publishing
    security: Name = ""

    def __post_init__(self) -> None:
        clip_strings(self, detail=DETAIL_MAX)
        force_setattr(self, "counters", bounded_counters(self.counters))


class Estop(Message, frozen=True):
    """Emergency stop (``engaged=True``) or its release (``engaged=False``), with who and why. A release in a cell
    with identities is the operator's, signed (:mod:`interfaces.arm_auth`): ``wall_ns`` its wall-clock stamp
    [ns since the epoch], ``certificate`` the operator's (PEM), ``signature`` ECDSA over cell, stamp, reason, source."""

    stamp_ns: int
    engaged: bool
    reason: Text
    source: Name = ""
    wall_ns: int = 0
    certificate: Certificate = b""
    signature: Signature = b""

    def __post_init__(self) -> None:
        clip_strings(self, reason=TEXT_MAX, source=NAME_MAX)


class ArmRequest(Message, frozen=True):
    """Operator -> a real-robot adapter: start commanding the robot (``armed=True``) or stop, with who and why.

    The adapter arms only when the robot's session says commanding is
    possible; it disarms by itself on a guard trip, controller loss or stop.
    """

    stamp_ns: int
    armed: bool
    reason: Text = ""
    source: Name = ""

    def __post_init__(self) -> None:
        clip_strings(self, reason=TEXT_MAX, source=NAME_MAX)


class Introduction(Message, frozen=True):
    """Controller or robot side -> the other, every 0.5 s, for authenticated commands (:mod:`interfaces.arm_auth`):
    role (``controller``, ``robot``), its certificate (PEM), the controller's session, the robot side's nonce."""

    stamp_ns: int
    role: Name
    certificate: Certificate
    session: Name = ""
    nonce: Nonce = b""


class SimTruth(Message, frozen=True):
    """Sim -> tests and reports: the true dirt per stain and the contact force. stain_ids and remaining: (k,) stain
    ids and remaining dirt fraction in [0, 1]; total_dirt: sum of the dirt grid [cell units]; contact_force_n:
    normal force of the eraser on the board [N] at this step; peak_force_n: the largest such force over every
    physics step since the last truth [N] (a truth every 100 ms would miss a 20 ms impact). centres_board_m and
    sizes_m: (k, 2) true stain centres in the board frame and (k,) their larger extents [m]; T_board_to_world: the
    board pose (tests compare perception against these)."""

    seq: int
    stamp_ns: int
    stain_ids: list[int]
    remaining: list[float]
    total_dirt: float
    contact_force_n: float
    robot_time_ns: int = 0
    centres_board_m: list[list[float]] = msgspec.field(default_factory=list)
    sizes_m: list[float] = msgspec.field(default_factory=list)
    T_board_to_world: Pose | None = None
    peak_force_n: float = 0.0

    def __post_init__(self) -> None:
        if len(self.stain_ids) != len(self.remaining):
            raise ValueError(f"{len(self.stain_ids)} stain_ids but {len(self.remaining)} remaining values")
        check_finite("remaining", self.remaining)
        check_finite("total_dirt/contact_force_n/peak_force_n",
                     (self.total_dirt, self.contact_force_n, self.peak_force_n))


#: Every message type, for decoders and tests.
MESSAGE_TYPES: tuple[type[Message], ...] = (
    RobotState, TorqueCommand, CameraFrame, Stains, ControllerStatus, ControllerTrace, ServiceStatus, Estop, SimTruth,
    ArmRequest, Introduction,
)

#: The largest payload [bytes] each message type may legitimately have. Receivers drop a larger one, counted,
#: before parsing it (a huge well-formed message must not stall a 1 kHz loop). Each bound is far above what
#: the cell sends: a 7-joint RobotState is about 0.4 kB, a TorqueCommand 0.1 kB, a 640x480 rgb8 frame 0.9 MB
#: (1920x1080 raw: 6.2 MB), a 50 ms trace batch about 15 kB, a status with its counters a few kB.
MAX_PAYLOAD_BYTES: dict[type[Message], int] = {
    RobotState: 16_384, TorqueCommand: 4_096, CameraFrame: 16_000_000, Stains: 262_144,
    ControllerStatus: 65_536, ControllerTrace: 1_048_576, ServiceStatus: 65_536, Estop: 8_192,
    SimTruth: 262_144, ArmRequest: 4_096, Introduction: 8_192,
}
