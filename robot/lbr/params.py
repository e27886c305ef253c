"""Parameters of the lbr_fri_ros2_stack adapter, the ``[lbr]`` config table, every key range-checked.

::

    [lbr]
    namespace = "lbr"                        # the stack's robot_name; topics /lbr/state, /lbr/command/torque
    state_topic = "state"
    torque_command_topic = "command/torque"
    wrench_topic = "force_torque_broadcaster/wrench"
    joint_states_topic = "joint_states"
    joint_names = ["lbr_A1", ..., "lbr_A7"]  # the stack's names, in our joint order
    wrench_source = "external_torque"        # or "stack": the bridge's WrenchStamped (world-aligned at the pad)
    velocity_cutoff_hz = 80.0                # low-pass of the position difference
    hold_damping_nm_s_rad = [4.0, 4.0, 2.0, 2.0, 0.5, 0.3, 0.1]   # safe hold per joint: tau = -D dq
    hold_timeout_s = 0.5                     # holding this long without a controller command: stop commanding
    stale_limit_s = 0.005                    # a controller answer later than this is not sent; hold instead
    max_joint_speed_scale = 0.8              # guard: this share of the description's joint speed limits
    speed_brake_share = 0.95                 # brake (hold) above this share of the guard's speed, or about to be
    tau_rate_nm_s = 5000.0                   # guard: torque change per second (the controller keeps to ~1000)
    limit_margin_rad = 0.05                  # guard: distance kept from the joint position limits
    arm = false                              # arm at start-up (else: an ArmRequest on robot/arm)
"""

from __future__ import annotations

from dataclasses import dataclass, field

from interfaces.config import check_range as _range
from interfaces.config import dataclass_from_table
from interfaces.errors import ConfigError

from .msgs import N_JOINTS, LbrTopics

WRENCH_SOURCES = ("external_torque", "stack")
DEFAULT_JOINT_NAMES = tuple(f"lbr_A{i}" for i in range(1, N_JOINTS + 1))
#: Safe-hold damping per joint [Nm s/rad]. An explicit -D dq at the FRI period is stable only for
#: D < 2 I / dt with I the joint's inertia: the wrist (A7 with an eraser, about 1e-3 kg m^2 in the
#: simulator, which has no rotor inertia) allows about 2, so the wrist gets a tenth of that; the real
#: robot's reflected motor inertia is far larger.
DEFAULT_HOLD_DAMPING = (4.0, 4.0, 2.0, 2.0, 0.5, 0.3, 0.1)


@dataclass(frozen=True)
class LbrParams:
    """The adapter's configuration (see the module docstring for each key)."""

    namespace: str = "lbr"
    state_topic: str = "state"
    torque_command_topic: str = "command/torque"
    wrench_topic: str = "force_torque_broadcaster/wrench"
    joint_states_topic: str = "joint_states"
    joint_names: tuple[str, ...] = field(default=DEFAULT_JOINT_NAMES)
    wrench_source: str = "external_torque"
    velocity_cutoff_hz: float = 80.0
    hold_damping_nm_s_rad: tuple[float, ...] = DEFAULT_HOLD_DAMPING
    hold_timeout_s: float = 0.5
    stale_limit_s: float = 0.005
    max_joint_speed_scale: float = 0.8
    speed_brake_share: float = 0.95
    tau_rate_nm_s: float = 5000.0
    limit_margin_rad: float = 0.05
    arm: bool = False

    def __post_init__(self) -> None:
        s = "lbr"
        for name in ("namespace", "state_topic", "torque_command_topic", "wrench_topic", "joint_states_topic"):
            v = getattr(self, name)
            if not isinstance(v, str) or (name != "namespace" and not v.strip("/")):
                raise ConfigError(f"[{s}] {name} must be a topic name (string), got {v!r}")
        names = tuple(self.joint_names) if isinstance(self.joint_names, (list, tuple)) else None
        if names is None or len(names) != N_JOINTS or len(set(names)) != N_JOINTS or \
                not all(isinstance(n, str) and n for n in names):
            raise ConfigError(f"[{s}] joint_names must be {N_JOINTS} distinct names (A1..A7 order), "
                              f"got {self.joint_names!r}")
        object.__setattr__(self, "joint_names", names)
        if self.wrench_source not in WRENCH_SOURCES:
            raise ConfigError(f"[{s}] wrench_source must be one of {WRENCH_SOURCES}, got {self.wrench_source!r}")
        _range(s, "velocity_cutoff_hz", self.velocity_cutoff_hz, 1.0, 500.0)
        d = self.hold_damping_nm_s_rad
        if not isinstance(d, (list, tuple)) or len(d) != N_JOINTS:
            raise ConfigError(f"[{s}] hold_damping_nm_s_rad must be {N_JOINTS} numbers (A1..A7), got {d!r}")
        for v in d:
            _range(s, "hold_damping_nm_s_rad", v, 0.0, 100.0)
        object.__setattr__(self, "hold_damping_nm_s_rad", tuple(float(v) for v in d))
        _range(s, "hold_timeout_s", self.hold_timeout_s, 0.001, 10.0)
        _range(s, "stale_limit_s", self.stale_limit_s, 0.0005, 1.0)
        _range(s, "max_joint_speed_scale", self.max_joint_speed_scale, 0.01, 1.0)
        _range(s, "speed_brake_share", self.speed_brake_share, 0.0, 1.0)
        _range(s, "tau_rate_nm_s", self.tau_rate_nm_s, 1.0, 100_000.0)
        _range(s, "limit_margin_rad", self.limit_margin_rad, 0.0, 0.5)
        if not isinstance(self.arm, bool):
            raise ConfigError(f"[{s}] arm must be true or false, got {self.arm!r}")

    @classmethod
    def from_table(cls, table) -> "LbrParams":
        return dataclass_from_table(cls, "lbr", table)

    @property
    def topics(self) -> LbrTopics:
        return LbrTopics(self.namespace, self.state_topic, self.torque_command_topic, self.wrench_topic,
                         self.joint_states_topic)
