"""The lbr stack's broadcasters in the lbr peer: ``LBRState``, the joint states and the estimated wrench.

:class:`Broadcasters` publishes what the controller manager's broadcasters do,
at their rates (``lbr/state`` every manager cycle, ``lbr/joint_states`` and
``lbr/force_torque_broadcaster/wrench`` every few), and keeps the wrench
estimate (``ft_update_rate_hz``) the force-torque broadcaster publishes.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import zenoh

from arm.robot_model import RobotModel
from robot.lbr.msgs import (
    DriveState,
    LbrState,
    SafetyState,
    encode_joint_state,
    encode_state,
    encode_wrench,
)
from robot.lbr.tip import tip_jacobian, tip_pose
from runtime.session import CONTROL_QOS

from .params import OPERATION_MODES, LbrPeerParams
from .stack import StackState, estimated_wrench


class Broadcasters:
    """The stack's publishers, their cadences and what they publish.

    p : the ``[lbr_peer]`` table; counters : the peer's counters (``states_published``, ``states_republished``);
    model : the simulated arm's description (the tip's pose and Jacobian); command_mode, control_mode : the robot's
    (the wire's integers). ft_every_fri : FRI cycles between wrench estimates; ft_every_cm, joints_every_cm :
    manager cycles between publications of the wrench and of the joint states; cycles : manager cycles published.
    frame_id : the wrench's frame; wrench_tip : (6,) the estimated wrench at ``lbr_link_ee``, tip axes [N, Nm];
    state_bytes : the last ``LBRState`` published, encoded (empty before the first).
    """

    __slots__ = ("p", "counters", "model", "command_mode", "control_mode", "ft_every_fri", "ft_every_cm",
                 "joints_every_cm", "cycles", "frame_id", "wrench_tip", "state_bytes", "_pub_state", "_pub_wrench",
                 "_pub_joints")

    def __init__(self, p: LbrPeerParams, raw: zenoh.Session, counters: Counter[str], model: RobotModel,
                 command_mode: int, control_mode: int) -> None:
        """``raw``: the zenoh session carrying the bridge's keys."""
        self.p = p
        self.counters = counters
        self.model = model
        self.command_mode = command_mode
        self.control_mode = control_mode
        self.ft_every_fri = max(round(1.0 / (p.sample_time_s * p.ft_update_rate_hz)), 1)
        self.ft_every_cm = max(round(p.update_rate_hz / p.ft_update_rate_hz), 1)
        self.joints_every_cm = max(round(p.update_rate_hz / p.joint_states_rate_hz), 1)
        self.cycles = 0
        self.wrench_tip = np.zeros(6)
        self.frame_id = f"{p.robot_name}/link_ee" if p.branch == "humble" else f"{p.robot_name}_link_ee"
        self.state_bytes = b""
        topics = p.topics
        self._pub_state = raw.declare_publisher(topics.key(topics.state), **CONTROL_QOS)
        self._pub_wrench = raw.declare_publisher(topics.key(topics.wrench))
        self._pub_joints = raw.declare_publisher(topics.key(topics.joint_states))

    def close(self) -> None:
        for pub in (self._pub_state, self._pub_wrench, self._pub_joints):
            pub.undeclare()

    def update_wrench(self, st: StackState) -> None:
        """The stack's wrench estimate from its state ``st``: its external torque through the tip's Jacobian."""
        q = st.q_rad
        _, R = tip_pose(self.model, q)
        p = self.p
        self.wrench_tip = estimated_wrench(tip_jacobian(self.model, q), st.tau_external_nm, R,
                                           p.ft_damping, p.ft_force_threshold_n, p.ft_torque_threshold_nm,
                                           threshold_in_tip=p.branch == "humble")

    def publish(self, st: StackState) -> None:
        """One manager cycle's publications: the stack's state ``st`` as its last FRI cycle left it (a lost link
        leaves it, time stamp included), the wrench and the joint states every few manager cycles."""
        self.cycles += 1
        k = self.cycles
        state = LbrState(
            sample_time_s=st.sample_time_s or self.p.sample_time_s, session_state=int(st.session),
            safety_state=int(SafetyState.NORMAL_OPERATION), operation_mode=int(OPERATION_MODES[self.p.operation_mode]),
            drive_state=int(DriveState.ACTIVE), client_command_mode=self.command_mode,
            control_mode=self.control_mode, stamp_ns=st.stamp_ns, q_rad=st.q_rad,
            tau_measured_nm=st.tau_measured_nm, tau_external_nm=st.tau_external_nm, q_commanded_rad=st.q_commanded_rad,
            tau_commanded_nm=st.tau_commanded_nm, connection_quality=st.connection_quality)
        self.state_bytes = encode_state(state, fri_major=self.p.fri_major, ipo_joint_position_rad=st.ipo_rad)
        self._pub_state.put(self.state_bytes)
        self.counters["states_published"] += 1
        if k % self.ft_every_cm == 0:
            self._pub_wrench.put(encode_wrench(self.frame_id, self.wrench_tip, st.stamp_ns))
        if k % self.joints_every_cm == 0:
            self._pub_joints.put(encode_joint_state(self.p.joint_names, st.q_rad, st.stamp_ns))

    def republish_state(self) -> None:
        """The last state again (same stamp), while an answer is awaited."""
        self._pub_state.put(self.state_bytes)
        self.counters["states_republished"] += 1
