"""What the stack and the robot must be before the adapter commands: one pure check, the first reason it may not.

Each refusal names the setting to change; the stack's code behind each
(lbr_fri_ros2_stack ``rolling`` 218d723) is in docs/real-robot.md, step 5:
nothing is published before COMMANDING_WAIT (system_interface.cpp:249-265),
commands are buffered only in COMMANDING_ACTIVE (system_interface.cpp:347-354),
the torque interface throws outside the TORQUE client command mode
(torque_command.cpp:11-19), torque overlay needs joint impedance (FRI SDK
friLBRCommand.h:118-127), ``open_loop: true`` publishes the stack's own
command as measured (async_client.cpp:82-93), a torque filter of alpha 0
never moves (filters.cpp:13-17,23-28), command mode needs a connection
quality of GOOD or better (friClientIf.h:74-75,83-84), a frozen clock is
a lost FRI link (:class:`~robot.lbr.watches.ClockWatch`), and a pad that
presses at rest is a stack holding a command away from the arm
(:func:`~robot.lbr.rest_checks.preload_refusal`).

:class:`ArmState` is what the adapter keeps of it: whether it commands, why
not, and the newest state at rest for the load-data note at arming.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .compensation import filter_alpha
from .msgs import (
    ClientCommandMode,
    ConnectionQuality,
    ControlMode,
    DriveState,
    LbrState,
    SafetyState,
    SessionState,
    enum_name,
)
from .params import LbrParams
from .rest_checks import load_note, preload_refusal
from .watches import ClockWatch

#: Joint speed [rad/s] under which the arm counts as at rest for arming on an FRI 2 state (no commanded
#: position in it: the stack's command is taken to be where the arm rests).
REST_SPEED_RAD_S = 0.05


def arming_refusal(st: LbrState | None, p: LbrParams, *, layout_error: str, names_ok: bool | None,
                   clock: ClockWatch, dq_rad_s: np.ndarray, wrench: np.ndarray | None = None) -> str | None:
    """Why the adapter may not arm on the newest state ``st`` (None: none yet), or None when it may.

    layout_error : the other FRI layout's message, if states came in it; names_ok : whether the joint names seen
    on ``joint_states`` are the configured ones (None: none seen); clock : the watch on the robot's clock;
    dq_rad_s : (7,) the estimated joint velocity [rad/s]; wrench : (6,) the pad wrench the external torque
    explains [N, Nm], world axes (None: not judged).
    """
    if layout_error:
        return layout_error
    if st is None:
        return "no robot state received yet (the stack publishes from COMMANDING_WAIT on)"
    if clock.frozen:
        return clock.reason
    if st.connection_quality < ConnectionQuality.GOOD:
        return (f"FRI connection quality {enum_name(ConnectionQuality, st.connection_quality)}: insufficient for "
                "command mode")
    if st.session_state != SessionState.COMMANDING_ACTIVE:
        return (f"session state {enum_name(SessionState, st.session_state)}: start the LBRServer application "
                "(JOINT_IMPEDANCE_CONTROL, TORQUE) on the smartPAD first")
    if st.safety_state != SafetyState.NORMAL_OPERATION:
        return f"safety state {enum_name(SafetyState, st.safety_state)}"
    if st.drive_state != DriveState.ACTIVE:
        return f"drives {enum_name(DriveState, st.drive_state)}"
    if st.client_command_mode != ClientCommandMode.TORQUE:
        return (f"client command mode {enum_name(ClientCommandMode, st.client_command_mode)}: choose TORQUE in the "
                "LBRServer app and client_command_mode: torque in the stack's config")
    if st.control_mode != ControlMode.JOINT_IMP_CONTROL_MODE:
        return (f"control mode {enum_name(ControlMode, st.control_mode)}: choose JOINT_IMPEDANCE_CONTROL in the "
                "LBRServer app (torque overlay needs it)")
    if p.open_loop:
        return ("[lbr] open_loop = true: with the stack's open_loop: true (its default) the published measured "
                "position is the stack's own command, not the encoders; set open_loop: false in the stack's "
                "config and [lbr] open_loop = false")
    for name, cutoff_hz in (("measured", p.measured_torque_cutoff_hz), ("external", p.external_torque_cutoff_hz)):
        if filter_alpha(cutoff_hz, st.sample_time_s) <= 1e-9:
            return (f"the stack's {name}_torque_cutoff_frequency {cutoff_hz:g} Hz at a "
                    f"{st.sample_time_s * 1e3:g} ms sample time gives its filter alpha 0: that torque never "
                    "changes; choose a cutoff below the sample rate")
    if names_ok is False:
        return f"joint names on {p.joint_states_topic} are not {list(p.joint_names)}"
    at_rest = float(np.max(np.abs(dq_rad_s))) <= REST_SPEED_RAD_S
    if st.q_commanded_rad is None and not at_rest:
        return "the arm is moving: an FRI 2 state has no commanded position, so arming waits for the arm at rest"
    if wrench is not None and at_rest:
        return preload_refusal(wrench, p.arm_preload_max_n, p.tool_mass_kg)
    return None


def left_commanding(st: LbrState) -> str | None:
    """Why an armed adapter must stop on the state ``st``: the session, the safety or the drives say the robot left
    commanding; or None."""
    if st.session_state == SessionState.COMMANDING_ACTIVE and st.safety_state == SafetyState.NORMAL_OPERATION and \
            st.drive_state == DriveState.ACTIVE:
        return None
    return (f"robot left commanding (session {enum_name(SessionState, st.session_state)}, safety "
            f"{enum_name(SafetyState, st.safety_state)}, drives {enum_name(DriveState, st.drive_state)})")


@dataclass(slots=True)
class ArmState:
    """Whether the adapter commands the robot, and what it says about it.

    armed : commanding torques; pending : to arm at the first controller command the robot allows (``--arm``);
    reason : why it does not command (the status's ``why=``; empty while armed); load_note : the tool mass the
    external torque at rest implied at arming, when off the load data (empty: none); rest_wrench : (6,) the pad
    wrench [N, Nm], world axes, in the newest state at rest while disarmed and pressing under
    ``arm_preload_max_n``; rest_ns : its robot time [ns] (None: no such state yet).
    """

    armed: bool = False
    pending: bool = False
    reason: str = "not armed yet"
    load_note: str = ""
    rest_wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))
    rest_ns: int | None = None

    def observe_rest(self, wrench: np.ndarray, dq_rad_s: np.ndarray, t_ns: int, preload_max_n: float) -> None:
        """A state of robot time ``t_ns`` with the pad ``wrench`` (6,) [N, Nm] and joint velocity ``dq_rad_s`` (7,)
        [rad/s]: kept as the rest when disarmed, at rest and pressing no more than ``preload_max_n`` [N]."""
        if not self.armed and float(np.max(np.abs(dq_rad_s))) <= REST_SPEED_RAD_S and \
                float(np.linalg.norm(wrench[:3])) <= preload_max_n:
            self.rest_wrench, self.rest_ns = wrench, t_ns

    def note_load(self, tool_mass_kg: float, tolerance_kg: float) -> str:
        """Set and return :attr:`load_note` from the newest rest, however old (an arm its load data leaves out sags
        once commanding starts); empty when the load data fits or no rest was seen."""
        w, rest_ns = self.rest_wrench, self.rest_ns
        self.load_note = "" if rest_ns is None else load_note(w, tool_mass_kg, tolerance_kg) or ""
        return self.load_note
