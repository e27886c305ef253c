"""Parameters of the lbr_fri_ros2_stack adapter, the ``[lbr]`` config table, every key range-checked.

::

    [lbr]
    namespace = "lbr"                        # the stack's robot_name; topics /lbr/state, /lbr/command/torque
    state_topic = "state"
    torque_command_topic = "command/torque"
    wrench_topic = "force_torque_broadcaster/wrench"
    joint_states_topic = "joint_states"
    branch = "rolling"                       # the stack's branch: "rolling" / "jazzy" (lbr_A1 ..) or "humble" (A1 ..)
    joint_names = []                         # [] : the branch's names; else 7 names in A1..A7 order
    fri_major = 1                            # the FRI client SDK the stack was built with: 1 or 2 (LBRState layout)
    open_loop = true                         # the stack's open_loop setting (its default: true; arming needs false)
    joint_stiffness_nm_rad = [200.0, ...]    # the LBRServer app's joint impedance stiffness, A1..A7
    pid_p = 0.1                              # the stack's pid_p (its joint_position PID; i and d must be 0)
    steer_share = 0.3                        # share of (q - stack command) one message closes
    steer_speed_rad_s = 0.5                  # ... at most this fast relative to the arm's speed (0: no bound)
    measured_torque_cutoff_hz = 10.0         # the stack's low-pass cutoffs (undone from consecutive states)
    external_torque_cutoff_hz = 10.0
    frozen_after_s = 0.05                    # measured positions unchanged this long under a changing overlay: disarm
    wrench_source = "external_torque"        # or "stack": the stack's WrenchStamped (tip frame, soft deadband)
    wrench_force_threshold_n = 2.0           # the stack's estimated_ft_sensor thresholds (force_*_th, torque_*_th)
    wrench_torque_threshold_nm = 0.5
    velocity_cutoff_hz = 80.0                # low-pass of the position difference
    hold_timeout_s = 0.5                     # holding this long without a controller command: disarm (the hold stays)
    lockstep_silence_s = 2.0                 # lock-step: no robot state this long [s, wall] disarms (hold_timeout_s)
    stale_limit_s = 0.005                    # a controller answer later than this is not sent; hold instead
    check_applied = true                     # a state whose commanded torque is no recent overlay of ours: not applied
    applied_tolerance_nm = 0.001             # ... "ours" within this on every joint, or half the robot's learned step,
    applied_tolerance_max_nm = 0.05          # ... but never wider than this
    applied_stall_s = 1.0                    # armed, no state on a recent overlay for this robot time: disarm, say why
    frozen_stamp_periods = 20                # states arriving, their time stamp still for this many periods: link lost
                                             # ... at least 20: at 1 ms, a 100 Hz manager re-publishes every 10
    disarm_at_quality = "POOR"               # FRI connection quality at which to disarm ("POOR" or "FAIR")
    max_joint_speed_scale = 0.8              # guard: this share of the description's joint speed limits
    speed_brake_share = 0.95                 # brake (hold) above this share of the guard's speed, or about to be
    tau_rate_nm_s = 5000.0                   # guard: torque change per second (the controller keeps to ~1000)
    limit_margin_rad = 0.05                  # guard: distance kept from the joint position limits
    arm_preload_max_n = 3.0                  # at rest, a pad force over this (external torque) refuses arming
    tool_mass_kg = 0.15                      # the tool's load data as set on the smartPAD (the eraser: 0.15 kg)
    tool_mass_tolerance_kg = 0.05            # the external torque at rest implying a tool further off: say so
    watchdog_after_s = 0.2                   # --watchdog: no command this long while states arrive: the release
    arm = false                              # arm at start-up (else: an ArmRequest on robot/arm)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from interfaces.errors import ConfigError
from runtime.config import In, check_declared, dataclass_from_table
from runtime.config import check_range as _range

from .msgs import FRI_MAJORS, N_JOINTS, LbrTopics, stack_joint_names

WRENCH_SOURCES = ("external_torque", "stack")
DISARM_QUALITIES = ("POOR", "FAIR")
BRANCHES = ("rolling", "jazzy", "humble")
DEFAULT_JOINT_NAMES = stack_joint_names("rolling")
#: LBRServer.java's JointImpedanceControlMode(200, 200, 200, 200, 200, 200, 200) (lbr-stack/fri ros2-fri-1.15:82,
#: fri-2.7:92) [Nm/rad].
APP_STIFFNESS = (200.0,) * N_JOINTS


@dataclass(frozen=True)
class LbrParams:
    """The adapter's configuration (see the module docstring for each key)."""

    namespace: str = "lbr"
    state_topic: str = "state"
    torque_command_topic: str = "command/torque"
    wrench_topic: str = "force_torque_broadcaster/wrench"
    joint_states_topic: str = "joint_states"
    branch: str = "rolling"
    joint_names: tuple[str, ...] = ()
    fri_major: int = 1
    open_loop: bool = True
    joint_stiffness_nm_rad: tuple[float, ...] = field(default=APP_STIFFNESS)
    pid_p: Annotated[float, In(1e-3, 1.0)] = 0.1
    steer_share: Annotated[float, In(0.01, 1.0)] = 0.3
    steer_speed_rad_s: Annotated[float, In(0.0, 100.0)] = 0.5
    measured_torque_cutoff_hz: Annotated[float, In(0.0, 10_000.0)] = 10.0
    external_torque_cutoff_hz: Annotated[float, In(0.0, 10_000.0)] = 10.0
    frozen_after_s: Annotated[float, In(0.005, 10.0)] = 0.05
    wrench_source: str = "external_torque"
    wrench_force_threshold_n: Annotated[float, In(0.0, 1000.0)] = 2.0
    wrench_torque_threshold_nm: Annotated[float, In(0.0, 100.0)] = 0.5
    velocity_cutoff_hz: Annotated[float, In(1.0, 500.0)] = 80.0
    hold_timeout_s: Annotated[float, In(0.001, 10.0)] = 0.5
    lockstep_silence_s: Annotated[float, In(0.001, 60.0)] = 2.0
    stale_limit_s: Annotated[float, In(0.0005, 1.0)] = 0.005
    check_applied: bool = True
    applied_tolerance_nm: Annotated[float, In(1e-9, 1.0)] = 0.001
    applied_tolerance_max_nm: Annotated[float, In(1e-9, 10.0)] = 0.05
    applied_stall_s: Annotated[float, In(0.01, 60.0)] = 1.0
    frozen_stamp_periods: Annotated[int, In(20, 100_000)] = 20
    disarm_at_quality: str = "POOR"
    max_joint_speed_scale: Annotated[float, In(0.01, 1.0)] = 0.8
    speed_brake_share: Annotated[float, In(0.0, 1.0)] = 0.95
    tau_rate_nm_s: Annotated[float, In(1.0, 100_000.0)] = 5000.0
    limit_margin_rad: Annotated[float, In(0.0, 0.5)] = 0.05
    arm_preload_max_n: Annotated[float, In(0.5, 100.0)] = 3.0
    tool_mass_kg: Annotated[float, In(0.0, 14.0)] = 0.15
    tool_mass_tolerance_kg: Annotated[float, In(0.001, 5.0)] = 0.05
    watchdog_after_s: Annotated[float, In(0.01, 10.0)] = 0.2
    arm: bool = False

    def __post_init__(self) -> None:
        s = "lbr"
        check_declared(self, s)
        for name in ("namespace", "state_topic", "torque_command_topic", "wrench_topic", "joint_states_topic"):
            v = getattr(self, name)
            if not isinstance(v, str) or (name != "namespace" and not v.strip("/")):
                raise ConfigError(f"[{s}] {name} must be a topic name (string), got {v!r}")
        if self.branch not in BRANCHES:
            raise ConfigError(f"[{s}] branch must be one of {BRANCHES}, got {self.branch!r}")
        names = tuple(self.joint_names) if isinstance(self.joint_names, (list, tuple)) else None
        if names == ():
            names = stack_joint_names(self.branch, self.namespace.strip("/").split("/")[-1] or "lbr")
        if names is None or len(names) != N_JOINTS or len(set(names)) != N_JOINTS or \
                not all(isinstance(n, str) and n for n in names):
            raise ConfigError(f"[{s}] joint_names must be {N_JOINTS} distinct names (A1..A7 order) or [] for the "
                              f"branch's, got {self.joint_names!r}")
        object.__setattr__(self, "joint_names", names)
        if self.fri_major not in FRI_MAJORS or isinstance(self.fri_major, bool):
            raise ConfigError(f"[{s}] fri_major must be one of {FRI_MAJORS}, got {self.fri_major!r}")
        for name in ("open_loop", "arm", "check_applied"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"[{s}] {name} must be true or false, got {getattr(self, name)!r}")
        if self.disarm_at_quality not in DISARM_QUALITIES:
            raise ConfigError(f"[{s}] disarm_at_quality must be one of {DISARM_QUALITIES}, got "
                              f"{self.disarm_at_quality!r}")
        if self.applied_tolerance_max_nm < self.applied_tolerance_nm:
            raise ConfigError(f"[{s}] applied_tolerance_max_nm must be at least applied_tolerance_nm "
                              f"({self.applied_tolerance_nm!r}), got {self.applied_tolerance_max_nm!r}")
        if self.wrench_source not in WRENCH_SOURCES:
            raise ConfigError(f"[{s}] wrench_source must be one of {WRENCH_SOURCES}, got {self.wrench_source!r}")
        k = self.joint_stiffness_nm_rad
        if not isinstance(k, (list, tuple)) or len(k) != N_JOINTS:
            raise ConfigError(f"[{s}] joint_stiffness_nm_rad must be {N_JOINTS} numbers (A1..A7), got {k!r}")
        for v in k:
            _range(s, "joint_stiffness_nm_rad", v, 0.0, 5000.0)
        object.__setattr__(self, "joint_stiffness_nm_rad", tuple(float(v) for v in k))

    @classmethod
    def from_table(cls, table) -> LbrParams:
        return dataclass_from_table(cls, "lbr", table)

    @property
    def topics(self) -> LbrTopics:
        return LbrTopics(self.namespace, self.state_topic, self.torque_command_topic, self.wrench_topic,
                         self.joint_states_topic)
