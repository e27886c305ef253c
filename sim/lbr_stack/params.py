"""The ``[lbr_peer]`` table: the simulated stack's configuration, with the stack's own defaults.

Each key mirrors a setting of lbr_fri_ros2_stack, of the robot-side
LBRServer application or of the session; the defaults are the stack's
(``rolling`` 218d723, ``humble`` cca24ae, lbr-stack/fri ``ros2-fri-1.15``
0a5e17a and ``fri-2.7`` 8298a4b). A cell that commands torques must change
some of them, as a user of the real stack must (docs/real-robot.md):
``client_command_mode = "torque"``, ``open_loop = false``, ``update_rate_hz``
at the FRI rate. docker-compose.yml's ``lbr-sim`` profile does.

namespace : the stack's robot name (topics ``/<namespace>/...``).
branch : ``rolling`` | ``jazzy`` | ``humble``: joint names ``<robot>_A1`` .. or ``A1`` ..
fri_major : 1 | 2: the FRI client SDK the stack was built with (lbr_fri_idl ``fri-1`` | ``fri-2`` LBRState).
mode : ``lockstep`` | ``realtime``. sample_time_s : the FRI send period the app runs with [s].
update_rate_hz : the controller manager's rate; 0: the branch's default (lbr_controllers.yaml:5: 100 on rolling,
200 on humble) [Hz].
manager_clock : ``own`` | ``fri``: in real time the controller manager runs on its own clock (``own``, as the real
one does: its update_rate on the robot PC's clock, not locked to the robot's FRI cycle), so states are published
twice or skipped against FRI cycles; ``fri`` locks it to every ``cm_every``-th FRI cycle. Lock-step always locks it.
manager_drift_ppm : how much slower the manager's clock runs than the robot's (its own clock only) [ppm].
client_command_mode : ``position`` | ``torque`` | ``wrench``: the stack's and the app's (they must agree).
control_mode : ``joint_impedance`` | ``position`` | ``cartesian_impedance``: the app's robot-side controller.
open_loop : the stack publishes its own joint position command as measured (lbr_system_config.yaml: true).
pid_p, pid_i, pid_d, pid_i_max, pid_i_min : the stack's PID on the commanded joint position.
measured_torque_cutoff_hz, external_torque_cutoff_hz : the stack's low-pass on those torques [Hz].
joint_stiffness_nm_rad : the app's joint impedance (LBRServer.java: 200 on every joint) [Nm/rad].
joint_damping_ratio : its damping (not set by the app: the robot's default, 0.7).
joint_damping_law : ``relative`` | ``absolute``: the robot damps the commanded position's rate against the arm's
(``D (dq_cmd - dq)``) or the arm's rate alone (``-D dq``); KUKA's law is in no public code (robot/lbr/release.py).
tool_load_error_kg : the tool's mass the robot's load data leaves out (0: set right; the eraser's 0.15: none set):
its weight is not compensated and shows in the external torque [kg].
ft_update_rate_hz, ft_damping, ft_force_threshold_n, ft_torque_threshold_nm : the stack's wrench estimate
(rate 0: the branch's, a 100 Hz thread on rolling, every controller-manager cycle on humble).
commanding_after_s : robot time at which the operator has started the app (COMMANDING_WAIT) [s].
commanding_wait_s : how long COMMANDING_WAIT lasts before the overlay is active [s].
stop_app_after_s : robot time at which the operator stops the app (0: never) [s].
link_lost_at_s, link_lost_for_s : robot time at which the FRI link is lost (0: never) and for how long (0: for
good) [s]: no packet either way; the stack's FRI thread waits and its manager re-publishes the last state.
quality_drop_at_s : robot time at which the connection quality falls to GOOD (0: never), then one level lower
every ``quality_step_s`` [s]; a lost link lowers it the same way. quality_abort_after_s : how long the robot
stays COMMANDING_ACTIVE with a quality below GOOD before it ends commanding [s].
commanded_torque_resolution_nm, commanded_torque_offset_nm : the ``commanded_torque`` the robot reports is the
overlay rounded to the resolution (0: exact) plus the offset on every joint [Nm]: a robot that does not echo.
operation_mode : ``T1`` | ``T2`` | ``AUT`` (reported). joint_states_rate_hz : JointState rate [Hz].
lockstep_wait_s : lock-step: wall time the robot waits for an answer before it runs on, re-applying the
last command as the stack does [s]. republish_s : lock-step re-send of an unanswered state [s].
status_rate_hz : the peer's ServiceStatus rate [Hz].
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any

from interfaces.errors import ConfigError
from robot.lbr.msgs import (
    FRI_MAJORS,
    N_JOINTS,
    ClientCommandMode,
    ControlMode,
    LbrTopics,
    OperationMode,
    stack_joint_names,
)
from runtime.config import In, check_declared, check_range, dataclass_from_table

MODES = ("lockstep", "realtime")
MANAGER_CLOCKS = ("own", "fri")
DAMPING_LAWS = ("relative", "absolute")
BRANCHES = ("rolling", "jazzy", "humble")
OPERATION_MODES = {"T1": OperationMode.TEST_MODE_1, "T2": OperationMode.TEST_MODE_2,
                   "AUT": OperationMode.AUTOMATIC_MODE}
COMMAND_MODES = {"position": ClientCommandMode.POSITION, "torque": ClientCommandMode.TORQUE,
                 "wrench": ClientCommandMode.WRENCH}
CONTROL_MODES = {"joint_impedance": ControlMode.JOINT_IMP_CONTROL_MODE,
                 "position": ControlMode.POSITION_CONTROL_MODE,
                 "cartesian_impedance": ControlMode.CART_IMP_CONTROL_MODE}
#: lbr_ros2_control/config/lbr_controllers.yaml:5 of each branch [Hz].
BRANCH_UPDATE_RATE_HZ = {"rolling": 100.0, "jazzy": 100.0, "humble": 200.0}
_NAMESPACE = re.compile(r"[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")


@dataclass(frozen=True)
class LbrPeerParams:
    """The ``[lbr_peer]`` table (module docstring); the arm, board and camera come from ``[sim]``."""

    namespace: str = "lbr"
    branch: str = "rolling"
    fri_major: int = 1
    mode: str = "lockstep"
    sample_time_s: Annotated[float, In(0.001, 0.01)] = 0.001
    update_rate_hz: Annotated[float, In(0.0, 10_000.0)] = 0.0
    manager_clock: str = "own"
    manager_drift_ppm: Annotated[float, In(-10_000.0, 10_000.0)] = 50.0
    client_command_mode: str = "position"
    control_mode: str = "joint_impedance"
    open_loop: bool = True
    pid_p: Annotated[float, In(0.0, 10.0)] = 0.1
    pid_i: Annotated[float, In(0.0, 10.0)] = 0.0
    pid_d: Annotated[float, In(0.0, 10.0)] = 0.0
    pid_i_max: Annotated[float, In(-10.0, 10.0)] = 0.0
    pid_i_min: float = 0.0
    measured_torque_cutoff_hz: Annotated[float, In(0.0, 10_000.0)] = 10.0
    external_torque_cutoff_hz: Annotated[float, In(0.0, 10_000.0)] = 10.0
    joint_stiffness_nm_rad: Annotated[float, In(0.0, 5000.0)] = 200.0
    joint_damping_ratio: Annotated[float, In(0.0, 1.0)] = 0.7
    joint_damping_law: str = "relative"
    tool_load_error_kg: Annotated[float, In(-14.0, 14.0)] = 0.0
    ft_update_rate_hz: float = 0.0
    ft_damping: Annotated[float, In(0.0, 10.0)] = 0.2
    ft_force_threshold_n: Annotated[float, In(0.0, 1000.0)] = 2.0
    ft_torque_threshold_nm: Annotated[float, In(0.0, 100.0)] = 0.5
    commanding_after_s: Annotated[float, In(0.0, 3600.0)] = 0.0
    commanding_wait_s: Annotated[float, In(0.0, 60.0)] = 0.05
    stop_app_after_s: Annotated[float, In(0.0, 1e6)] = 0.0
    link_lost_at_s: Annotated[float, In(0.0, 1e6)] = 0.0
    link_lost_for_s: Annotated[float, In(0.0, 1e6)] = 0.0
    quality_drop_at_s: Annotated[float, In(0.0, 1e6)] = 0.0
    quality_step_s: Annotated[float, In(0.001, 60.0)] = 0.1
    quality_abort_after_s: Annotated[float, In(0.0, 60.0)] = 0.0
    commanded_torque_resolution_nm: Annotated[float, In(0.0, 10.0)] = 0.0
    commanded_torque_offset_nm: Annotated[float, In(-100.0, 100.0)] = 0.0
    operation_mode: str = "T1"
    joint_states_rate_hz: float = 100.0
    lockstep_wait_s: Annotated[float, In(0.001, 10.0)] = 0.5
    republish_s: Annotated[float, In(0.001, 10.0)] = 0.05
    status_rate_hz: Annotated[float, In(0.1, 100.0)] = 2.0

    def __post_init__(self) -> None:
        s = "lbr_peer"
        check_declared(self, s)
        if not isinstance(self.namespace, str) or not _NAMESPACE.fullmatch(self.namespace.strip("/")):
            raise ConfigError(f"[{s}] namespace must be a ROS name like 'lbr' (letters, digits, '_', "
                              f"'/'-separated), got {self.namespace!r}")
        object.__setattr__(self, "namespace", self.namespace.strip("/"))
        for name, allowed in (("mode", MODES), ("branch", BRANCHES), ("operation_mode", tuple(OPERATION_MODES)),
                              ("manager_clock", MANAGER_CLOCKS), ("joint_damping_law", DAMPING_LAWS),
                              ("client_command_mode", tuple(COMMAND_MODES)),
                              ("control_mode", tuple(CONTROL_MODES))):
            if getattr(self, name) not in allowed:
                raise ConfigError(f"[{s}] {name} must be one of {allowed}, got {getattr(self, name)!r}")
        if self.fri_major not in FRI_MAJORS or isinstance(self.fri_major, bool):
            raise ConfigError(f"[{s}] fri_major must be one of {FRI_MAJORS}, got {self.fri_major!r}")
        if not isinstance(self.open_loop, bool):
            raise ConfigError(f"[{s}] open_loop must be true or false, got {self.open_loop!r}")
        rate = 1.0 / self.sample_time_s
        if self.update_rate_hz == 0:
            object.__setattr__(self, "update_rate_hz", BRANCH_UPDATE_RATE_HZ[self.branch])
        elif self.update_rate_hz < 1.0:
            raise ConfigError(f"[{s}] update_rate_hz must be 0 (the branch's) or at least 1 Hz, got "
                              f"{self.update_rate_hz!r}")
        if self.ft_update_rate_hz == 0:
            object.__setattr__(self, "ft_update_rate_hz",
                               min(self.update_rate_hz if self.branch == "humble" else 100.0, rate))
        check_range(s, "ft_update_rate_hz", self.ft_update_rate_hz, 0.1, rate)
        check_range(s, "joint_states_rate_hz", self.joint_states_rate_hz, 0.1, rate)
        check_range(s, "pid_i_min", self.pid_i_min, -10.0, self.pid_i_max)

    @property
    def topics(self) -> LbrTopics:
        return LbrTopics(self.namespace)

    @property
    def robot_name(self) -> str:
        """The prefix of the stack's joint and link names (the last chunk of the namespace)."""
        return self.namespace.split("/")[-1]

    @property
    def joint_names(self) -> tuple[str, ...]:
        return stack_joint_names(self.branch, self.robot_name)

    @property
    def cm_every(self) -> int:
        """FRI cycles per controller-manager cycle (at least 1: a faster manager re-reads the same state)."""
        return max(int(round(1.0 / (self.update_rate_hz * self.sample_time_s))), 1)

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> LbrPeerParams:
        return dataclass_from_table(cls, "lbr_peer", table)


assert len(LbrPeerParams().joint_names) == N_JOINTS
