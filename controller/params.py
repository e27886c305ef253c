"""Parameters of ``lamps controller``, one frozen dataclass per concern, from the ``[controller]`` config table.

Layout (every key optional)::

    [controller]
    mode = "lockstep"          # answer each robot state; or "realtime": own 1 kHz clock
    rate_hz = 1000.0
    skill = ""                 # skill file from lamps learn / lamps demo (required to start)
    stains_from = "perception" # or "truth": take stains from sim/truth (tests, before perception exists)
    [controller.impedance]  stiffness_n_m, stiffness_nm_rad, damping_factor, nullspace_stiffness_nm_rad
    [controller.force]      target_n, cap_n, kp, ki, integral_limit_n, contact_threshold_n, ...
    [controller.limits]     torque_rate_nm_per_ms, joint_margin_rad, max_speed_m_s, max_position_error_m, ...
    [controller.executor]   standoff_m, approach_speed_m_s, wipe_timeout_s, kappa_remaining, air, ...
    [controller.planner]    amplitude_fraction, min_amplitude_m, max_amplitude_m, order, ...
    [controller.model]      enabled, integral_s, bound_share, warn_s (the arm's model correction, tool estimate)
    [controller.teach]      damping_n_s_m, damping_nm_s_rad, joint_damping_nm_s_rad, force_cap_n (lamps teach)

Every value is checked when built; an unknown key or a value out of range
raises :class:`~interfaces.errors.ConfigError` naming the key and its range.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any

from controller.control.model_correction import CorrectionParams
from controller.control.params import ControlConfigError, ImpedanceParams
from interfaces.errors import ConfigError
from lampskit.core.planner_types import PlannerParams
from lampskit.errors import PlanningError
from runtime.config import In, check_declared, dataclass_from_table
from runtime.config import check_range as _range

MODES = ("lockstep", "realtime")
#: No robot state this long [s, wall] is a lost robot, per mode (``robot_lost_s = 0``).
ROBOT_LOST_DEFAULT_S = {"lockstep": 2.0, "realtime": 0.5}
#: 20 min at 1 kHz, 190 MB of trace.
MAX_TRACE_TICKS = 1_200_000
#: A rest-to-rest quintic's peak speed over its mean speed.
QUINTIC_PEAK_SPEED = 1.875
STAIN_SOURCES = ("perception", "truth")


@dataclass(frozen=True)
class ForceParams:
    """Normal force regulation.

    target_n : force pressed on the board while wiping [N]; cap_n : above
    this (filtered) the controller lifts off and faults [N]; kp [N/N], ki
    [1/s], integral_limit_n [N]: the PI regulator; contact_threshold_n :
    force that counts as touching the board while descending [N];
    normal_damping_1_s : damping of motion along the normal while
    force-controlled [1/s, times the task inertia]; ramp_s : time the target
    ramps in and out over [s]; contact_loss_s : while pressing, a measured
    force under the contact threshold for this long is a fault (contact
    lost) [s].
    """

    target_n: Annotated[float, In(0.5, 150.0)] = 10.0
    cap_n: Annotated[float, In(1.0, 150.0)] = 40.0
    kp: Annotated[float, In(0.0, 5.0)] = 0.3
    ki: Annotated[float, In(0.0, 100.0)] = 8.0
    integral_limit_n: Annotated[float, In(0.0, 100.0)] = 8.0
    contact_threshold_n: float = 2.0
    normal_damping_1_s: Annotated[float, In(0.0, 500.0)] = 40.0
    ramp_s: Annotated[float, In(0.01, 5.0)] = 0.3
    filter_s: Annotated[float, In(0.0, 0.1)] = 0.005
    contact_loss_s: Annotated[float, In(0.01, 10.0)] = 0.3

    def __post_init__(self) -> None:
        s = "controller.force"
        check_declared(self, s)
        if self.target_n >= self.cap_n:
            raise ConfigError(f"[{s}] target_n ({self.target_n} N) must be below cap_n ({self.cap_n} N)")
        _range(s, "contact_threshold_n", self.contact_threshold_n, 0.1, self.target_n)


@dataclass(frozen=True)
class LimitParams:
    """Limits beyond the description's absolute torques.

    torque_rate_nm_per_ms : largest change of a joint torque per ms [Nm/ms];
    joint_margin_rad : repulsion starts this close to a position limit
    [rad], with joint_margin_stiffness_nm_rad and joint_margin_damping_nm_s_rad;
    clearance_zone_rad, singular_joints (1-based), singular_clearance_rad :
    the nullspace posture keeps joints this far from their limits and the
    listed joints this far from zero (the arm stretched at them), with
    clearance_stiffness_nm_rad and clearance_damping_nm_s_rad (0 stiffness:
    off; :func:`controller.control.limits.clearance_torque`), faded out
    while the fastest joint runs at 0.2 below clearance_speed_share to
    clearance_speed_share of its speed limit, and while the self-motion it
    drives in the nullspace turns a joint at 0.1 below self_motion_share to
    self_motion_share of its speed limit; any self-motion above
    self_motion_share is braked with self_motion_brake_1_s [1/s] on the
    arm's inertia (:func:`controller.control.limits.self_motion_limit`);
    rest_plan_rate_rad_s : the posture's rest pose moves from the first
    state to the one planned out of the clearance's zones
    (:func:`arm.posture.planned_rest_posture`) at this joint speed [rad/s]
    (0: no plan, the first state stays the rest pose);
    max_speed_m_s : the pad is braked above this Cartesian speed [m/s];
    reference_joint_speed_share : the skill is slowed down (time scaling)
    where its reference would ask a joint for more than this share of its
    speed limit (the description's; 10 turns it off); joint_speed_share : a joint is braked
    above this share, with joint_speed_brake_1_s [1/s] on its own inertia;
    both below the real-robot adapter's guard (0.8 of the limit);
    max_position_error_m, max_rotation_error_rad : the pose error is clipped
    to these (bounded pull towards a far reference); gain_ramp_s : the
    stiffness ramps up over this long after (re)starting [s];
    disturbance_share : a joint torque that neither the command nor the
    measured contact explains (:mod:`controller.control.watch`), filtered
    over disturbance_filter_s [s], above this share of the joint's torque
    limit for disturbance_persist_s [s] is a fault (the arm is not doing
    what it was told); 10 turns the watch off.
    overload_share : in real time, a share of the robot's states left
    unanswered (filtered over overload_filter_s [s] of robot time) above this
    for overload_persist_s [s] is a fault: the loop cannot keep up, so the
    pad lifts off under control instead of wiping on with stale torques
    (1 = off). Before that the motion slows: above overload_slow_share the
    skill's time scale falls linearly to overload_min_scale at
    overload_share (:func:`controller.control.limits.load_scale`). After an
    overload FAULT (the pad lifted), a share below overload_slow_share for
    overload_recover_s [s] of robot time starts again from the measured pose
    (0: the FAULT holds until the controller is restarted).
    """

    torque_rate_nm_per_ms: Annotated[float, In(0.01, 50.0)] = 1.0
    joint_margin_rad: Annotated[float, In(0.01, 0.5)] = 0.12
    joint_margin_stiffness_nm_rad: Annotated[float, In(0.0, 5000.0)] = 300.0
    joint_margin_damping_nm_s_rad: Annotated[float, In(0.0, 500.0)] = 10.0
    clearance_zone_rad: Annotated[float, In(0.01, 1.5)] = 0.5
    singular_joints: tuple[int, ...] = (2, 4, 6)
    singular_clearance_rad: Annotated[float, In(0.0, 1.0)] = 0.6
    clearance_stiffness_nm_rad: Annotated[float, In(0.0, 500.0)] = 40.0
    clearance_damping_nm_s_rad: Annotated[float, In(0.0, 100.0)] = 6.0
    clearance_speed_share: Annotated[float, In(0.2, 1.0)] = 1.0
    self_motion_share: Annotated[float, In(0.1, 10.0)] = 0.2
    self_motion_brake_1_s: Annotated[float, In(0.0, 400.0)] = 50.0
    rest_plan_rate_rad_s: Annotated[float, In(0.0, 2.0)] = 0.25
    max_speed_m_s: Annotated[float, In(0.05, 2.0)] = 0.6
    speed_brake_gain_n_s_m: Annotated[float, In(0.0, 5000.0)] = 200.0
    reference_joint_speed_share: Annotated[float, In(0.05, 10.0)] = 0.6
    joint_speed_share: Annotated[float, In(0.1, 1.0)] = 0.65
    joint_speed_brake_1_s: Annotated[float, In(0.0, 400.0)] = 150.0
    max_position_error_m: Annotated[float, In(0.005, 0.5)] = 0.05
    max_rotation_error_rad: Annotated[float, In(0.05, 3.2)] = 0.3
    gain_ramp_s: Annotated[float, In(0.0, 10.0)] = 0.5
    disturbance_share: Annotated[float, In(0.02, 10.0)] = 0.1
    disturbance_filter_s: Annotated[float, In(0.001, 1.0)] = 0.02
    disturbance_persist_s: Annotated[float, In(0.0, 5.0)] = 0.05
    overload_share: Annotated[float, In(0.01, 1.0)] = 0.3
    overload_filter_s: Annotated[float, In(0.01, 10.0)] = 0.5
    overload_persist_s: Annotated[float, In(0.0, 60.0)] = 1.0
    overload_slow_share: Annotated[float, In(0.0, 1.0)] = 0.05
    overload_min_scale: Annotated[float, In(0.05, 1.0)] = 0.4
    overload_recover_s: Annotated[float, In(0.0, 600.0)] = 3.0

    def __post_init__(self) -> None:
        s = "controller.limits"
        check_declared(self, s)
        joints = self.singular_joints
        if not isinstance(joints, (list, tuple)) or not all(isinstance(j, int) and not isinstance(j, bool)
                                                            and 1 <= j <= 7 for j in joints) \
                or len(set(joints)) != len(joints):
            raise ControlConfigError(f"{s}.singular_joints must be distinct joint numbers 1-7 (the iiwa: [2, 4, 6]), "
                                     f"got {joints!r}")
        object.__setattr__(self, "singular_joints", tuple(joints))
        if self.overload_slow_share >= self.overload_share:
            raise ControlConfigError(f"{s}.overload_slow_share must be below overload_share ({self.overload_share:g}), "
                              f"got {self.overload_slow_share:g}: the motion slows before the overload ends the run")


@dataclass(frozen=True)
class ExecutorParams:
    """The skill executor (paper section II-C) around the learned MPs.

    standoff_m : hover height over the board for approach, retreat, pause
    [m]; approach_speed_m_s : mean speed of free moves [m/s];
    descend_speed_m_s : speed towards the board until contact [m/s] (the
    first touch's force peak grows with it: up to 1,000 N per m/s over the
    random boards, 19.8 N at 0.02 m/s; at 0.014, 12-14 N); lift_speed_m_s :
    mean speed of a lift off the board to ``standoff_m`` [m/s];
    turn_rate_rad_s : mean angular speed of free moves [rad/s];
    wipe_timeout_s : one pass over a stain lasts at most this long without
    kappa [s] (the eraser hides the stain from the camera: it is judged once
    the pad has left); pass_cycles : ... and at most this many cycles of the
    periodic MP (the felt cleans a stain in about as many cycles whatever its
    size and speed: in the simulated cells the dirt fell below kappa's level
    after 1.4-2.4 cycles of a pass; the periodic MP wipes on for up to one
    more cycle until its phase heads for the next stain, so 2 is 2-3 cycles:
    3 had every stain wiped on clean for a cycle, 10 % of the robot time
    over 24 campaign cells, with no more re-passes); recheck_s : a stain left without kappa is wiped again
    only after this long [s] (perception's time to look at it), after the
    others; max_passes : passes before a stain is given up;
    look_clearance_m : after the last pass with stains still without kappa,
    the pad waits this far beyond their edge on the robot base's side, where
    the arm does not hide them from the camera [m] (0: where the pass ended);
    kappa_remaining : with ``stains_from = "truth"``, a stain is done when
    its remaining dirt is at most this fraction; air : wipe ``air_height_m``
    above the board without touching it (a dry run); stop_s : time to brake
    an in-plane motion to rest on a pause, fault or e-stop [s];
    estop_ramp_s : force ramp-down on an e-stop [s]; contact_search_m : how
    far below the expected surface the descent goes before it gives up [m];
    creep_height_m : height above the expected board surface where the
    descent has slowed to ``descend_speed_m_s`` and goes on at that speed
    until contact [m] (cover the board pose's uncertainty: on the tilted
    board the pad met the surface up to 11 mm above the expected height, at
    the end of a fast descent to 8 mm, 46-50 N); first_creep_height_m : the
    same for the first touch of a board, before its surface has been found
    (:mod:`controller.surface_touch`: perception's board lay up to 20 mm
    behind the surface on random boards) [m]; survey_s : before
    the first approach the pad flies to the look point of the whole board
    (``look_clearance_m`` beyond its edge on the robot base's side, where the
    arm hides none of it from the camera) and waits this long for perception
    to report every stain before the skill is planned [s]; with none
    reported, once more from where the arm hides what it hid there (0: plan
    over the stains reported at the start, wherever the arm is); board_jump_m,
    board_jump_rad : a reported board pose this far from the adopted one [m]
    or turned this much [rad] is a jump: never adopted at once (lift off
    first when pressing), only after it has held still for
    ``board_confirm_s`` [s] with the pad in the air, and then surveyed
    before any approach; board_reach_m : a board whose centre is farther
    from the robot base is refused [m].
    """

    standoff_m: Annotated[float, In(0.005, 0.3)] = 0.04
    approach_speed_m_s: Annotated[float, In(0.01, 1.0)] = 0.15
    descend_speed_m_s: Annotated[float, In(0.005, 0.3)] = 0.014
    lift_speed_m_s: Annotated[float, In(0.005, 0.3)] = 0.02
    creep_height_m: float = 0.016
    first_creep_height_m: float = 0.035
    turn_rate_rad_s: Annotated[float, In(0.05, 3.0)] = 0.6
    wipe_timeout_s: Annotated[float, In(0.5, 3600.0)] = 2.5
    pass_cycles: Annotated[float, In(0.5, 1e6)] = 2.0
    recheck_s: Annotated[float, In(0.0, 60.0)] = 1.0
    max_passes: Annotated[int, In(1, 100)] = 6
    look_clearance_m: Annotated[float, In(0.0, 1.0)] = 0.1
    kappa_remaining: Annotated[float, In(0.0, 1.0)] = 0.03
    air: bool = False
    air_height_m: Annotated[float, In(0.005, 0.3)] = 0.03
    stop_s: Annotated[float, In(0.05, 3.0)] = 0.3
    estop_ramp_s: Annotated[float, In(0.01, 1.0)] = 0.1
    contact_search_m: Annotated[float, In(0.005, 0.2)] = 0.03
    survey_s: Annotated[float, In(0.0, 60.0)] = 1.0
    board_jump_m: Annotated[float, In(0.005, 10.0)] = 0.05
    board_jump_rad: Annotated[float, In(0.02, 3.2)] = 0.1
    board_confirm_s: Annotated[float, In(0.0, 600.0)] = 2.0
    board_reach_m: Annotated[float, In(0.3, 10.0)] = 1.3

    def __post_init__(self) -> None:
        s = "controller.executor"
        check_declared(self, s)
        if not isinstance(self.air, bool):
            raise ConfigError(f"[{s}] air must be true or false, got {self.air!r}")
        _range(s, "creep_height_m", self.creep_height_m, 0.001, self.standoff_m)
        _range(s, "first_creep_height_m", self.first_creep_height_m, self.creep_height_m, self.standoff_m)


@dataclass(frozen=True)
class TeachParams:
    """Hand-guiding (``lamps teach``, :mod:`controller.teach`): no stiffness, light damping, the guards on.

    damping_n_s_m : translational damping at the pad [N s/m]; damping_nm_s_rad :
    rotational [Nm s/rad]; joint_damping_nm_s_rad : on every joint [Nm s/rad]
    (the elbow's nullspace motion, which no Cartesian term sees). A person
    guiding a 4 kg effective pad mass feels 25 N s/m as a drag of 5 N at
    0.2 m/s (a wiping stroke) that brings the pad to rest within about a
    second when let go. force_cap_n : a contact force (the measured wrench's
    force, world axes) above this, filtered over ``controller.force.filter_s``,
    is a FAULT: the arm holds where it is (joint-space spring, natural
    frequency hold_1_s [rad/s], critically damped) until the teach run ends.
    """

    damping_n_s_m: Annotated[float, In(0.0, 500.0)] = 25.0
    damping_nm_s_rad: Annotated[float, In(0.0, 50.0)] = 1.0
    joint_damping_nm_s_rad: Annotated[float, In(0.0, 50.0)] = 0.5
    force_cap_n: Annotated[float, In(1.0, 150.0)] = 40.0
    hold_1_s: Annotated[float, In(1.0, 50.0)] = 10.0

    def __post_init__(self) -> None:
        check_declared(self, "controller.teach")


@dataclass(frozen=True)
class ControllerParams:
    """The whole controller.

    mode : ``lockstep`` (answer each robot state, time from the robot's
    clock) or ``realtime`` (the robot's clock drives the loop: each newest
    state answered as it arrives; states never answered are overruns).
    rate_hz : nominal control rate: the tick cost is checked against it at
    start-up, and in real time the loop does its bookkeeping (e-stop, status,
    robot-lost watch) at least this often when no state comes. skill : skill file path (required before the
    controller starts; "" only for configs that set it later). stains_from : ``perception`` or ``truth``.
    state_timeout_s : real time: a robot state older than this is not
    answered (nothing new is sent; counted); 0 = five periods. robot_lost_s : no robot state
    for this long (wall time, both modes; the lock-step sim re-sends its
    state every 0.1 s while it waits) -> FAULT, and a restart from the
    measured pose when states come back; 0 = the mode's default,
    :data:`ROBOT_LOST_DEFAULT_S` (real time 0.5 s; lock-step 2 s: the sim
    waits for each answer, so a silence moves nothing and only a dead peer
    matters, not one starved for half a second on a loaded machine).
    stains_timeout_s : no stains update this long -> PAUSED. status_rate_hz : ControllerStatus rate.
    max_ticks : stop after this many ticks (0 = run until stopped). trace_ticks : keep this many ticks of
    reference/measurement trace in memory (0 = none). publish_trace : publish
    every tick's trace row on ``controller/trace`` in batches with each
    status (what ``lamps up`` records and reports from).
    """

    mode: str = "lockstep"
    rate_hz: Annotated[float, In(100.0, 10000.0)] = 1000.0
    skill: str = ""
    stains_from: str = "perception"
    state_timeout_s: float = 0.0
    robot_lost_s: float = 0.0
    stains_timeout_s: Annotated[float, In(0.05, 3600.0)] = 1.0
    status_rate_hz: Annotated[float, In(0.5, 200.0)] = 20.0
    max_ticks: Annotated[int, In(0, 10**9)] = 0
    trace_ticks: Annotated[int, In(0, MAX_TRACE_TICKS)] = 0
    publish_trace: bool = True
    impedance: ImpedanceParams = field(default_factory=ImpedanceParams)
    force: ForceParams = field(default_factory=ForceParams)
    limits: LimitParams = field(default_factory=LimitParams)
    executor: ExecutorParams = field(default_factory=ExecutorParams)
    planner: PlannerParams = field(default_factory=PlannerParams)
    teach: TeachParams = field(default_factory=TeachParams)
    model: CorrectionParams = field(default_factory=CorrectionParams)

    def __post_init__(self) -> None:
        s = "controller"
        check_declared(self, s)
        if self.mode not in MODES:
            raise ConfigError(f"[{s}] mode must be one of {MODES}, got {self.mode!r}")
        if not isinstance(self.skill, str):
            raise ConfigError(f"[{s}] skill must be a file path (string), got {self.skill!r}")
        if self.stains_from not in STAIN_SOURCES:
            raise ConfigError(f"[{s}] stains_from must be one of {STAIN_SOURCES}, got {self.stains_from!r}")
        if self.state_timeout_s != 0.0:
            _range(s, "state_timeout_s", self.state_timeout_s, 1.5 / self.rate_hz, 1.0)
        if self.robot_lost_s != 0.0:
            _range(s, "robot_lost_s", self.robot_lost_s, 0.15, 60.0)
        if not isinstance(self.publish_trace, bool):
            raise ConfigError(f"[{s}] publish_trace must be true or false, got {self.publish_trace!r}")
        peak = QUINTIC_PEAK_SPEED * self.executor.approach_speed_m_s
        if peak > self.limits.max_speed_m_s:
            raise ConfigError(
                f"[controller.executor] approach_speed_m_s = {self.executor.approach_speed_m_s} peaks at "
                f"{peak:.2f} m/s, above [controller.limits] max_speed_m_s = {self.limits.max_speed_m_s}: the speed "
                "brake would fight it")

    @property
    def state_timeout_or_default_s(self) -> float:
        return self.state_timeout_s or 5.0 / self.rate_hz

    @property
    def robot_lost_or_default_s(self) -> float:
        return self.robot_lost_s or ROBOT_LOST_DEFAULT_S[self.mode]

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> ControllerParams:
        """The ``[controller]`` table (with its sub-tables) as parameters."""
        if not isinstance(table, Mapping):
            raise ConfigError(f"[controller] must be a table, got {type(table).__name__}")
        table = dict(table)
        subs = {"impedance": ImpedanceParams, "force": ForceParams, "limits": LimitParams,
                "executor": ExecutorParams, "planner": PlannerParams, "teach": TeachParams,
                "model": CorrectionParams}
        parts = {}
        for name, kind in subs.items():
            try:
                parts[name] = dataclass_from_table(kind, f"controller.{name}", table.pop(name, {}))
            except (ControlConfigError, PlanningError) as exc:  # the learning side's own checks
                raise ConfigError(f"[controller.{name}] {exc}") from None
            except TypeError as exc:
                raise ConfigError(f"[controller.{name}] {exc}") from None
        return dataclass_from_table(cls, "controller", table, **parts)
