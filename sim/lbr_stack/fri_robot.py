"""The robot behind FRI in the lbr peer: the LBRServer app's joint impedance on the simulated arm.

:class:`FriRobot` is what the stack's FRI client talks to (:mod:`sim.lbr_stack.peer`
runs it): the app's client command and control modes, the command it last got
and applies over the physics steps of one FRI period (``tau = overlay + K (q_cmd - q)
+ D (dq_cmd - dq)`` plus the robot's gravity compensation, :func:`~.stack.joint_impedance_torque`),
the arm held on its brakes otherwise, and the external torque it estimates.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel
from robot.lbr.msgs import N_JOINTS
from sim.core import SimCore

from .params import COMMAND_MODES, CONTROL_MODES, LbrPeerParams
from .stack import FriCommand, impedance_damping, joint_impedance_torque, reported_commanded_torque


def external_torque_nm(jacobian: np.ndarray, wrench: np.ndarray) -> np.ndarray:
    """``tau_ext = J^T w`` (7,) [Nm]: the joint torques of a wrench the environment exerts on the tool.

    jacobian : (6, 7) of the TCP, linear rows first, world-aligned axes; wrench : (6,) force [N] then
    torque about the TCP [Nm], world axes (virtual work: ``tau_ext . dq = w . J dq``).
    """
    return jacobian.T @ wrench


class FriRobot:
    """The robot's side of FRI on the simulated arm (joint space, 7 joints, SI units).

    p : the ``[lbr_peer]`` table; core : the simulated cell it steps; model : the simulated arm's description
    (its drives' rotor inertia in M), for Jacobians and inertia; substeps : physics steps per FRI period;
    dt_s : the FRI period [s]. command_mode, control_mode : the app's client command mode and control mode
    (the wire's integers). stiffness : (7,) the app's joint stiffness K [Nm/rad]; zeros : (7,) zeros.
    command : the FRI command the robot got in its last commanding cycle (None while it holds).
    spring_max_nm : the largest joint spring torque ``K |q_cmd - q|`` it applied [Nm].
    """

    __slots__ = ("p", "core", "model", "substeps", "dt_s", "command_mode", "control_mode", "stiffness", "zeros",
                 "command", "spring_max_nm")

    def __init__(self, p: LbrPeerParams, core: SimCore, substeps: int) -> None:
        self.p = p
        self.core = core
        self.model = RobotModel(joints=core.joints)  # the simulated drives' rotor inertia in M
        self.substeps = substeps
        self.dt_s = p.sample_time_s
        self.command_mode = int(COMMAND_MODES[p.client_command_mode])
        self.control_mode = int(CONTROL_MODES[p.control_mode])
        self.stiffness = np.full(N_JOINTS, p.joint_stiffness_nm_rad)
        self.zeros = np.zeros(N_JOINTS)
        self.command: FriCommand | None = None
        self.spring_max_nm = 0.0

    def reported_torque(self) -> np.ndarray:
        """(7,) [Nm] the ``commanded_torque`` the robot reports: its last command's overlay (zeros without one)."""
        last = self.command
        return reported_commanded_torque(last.torque if last is not None else self.zeros,
                                         self.p.commanded_torque_resolution_nm, self.p.commanded_torque_offset_nm)

    def external_torque(self) -> np.ndarray:
        """(7,) [Nm] the external torque the robot estimates: the pad's contact wrench through the Jacobian, plus
        the tool weight its load data leaves out (:meth:`unloaded_torque`)."""
        o = self.core.out
        if np.any(o.wrench):
            return external_torque_nm(self.model.tcp_jacobian(o.q), o.wrench) + self.unloaded_torque()
        return self.unloaded_torque()  # free space: no contact

    def unloaded_torque(self) -> np.ndarray:
        """(7,) [Nm] the weight of the tool mass the robot's load data leaves out (``tool_load_error_kg``), at the
        pad: not compensated by the robot, so it is in the torque it applies and in the external torque."""
        m = self.p.tool_load_error_kg
        if m == 0.0:
            return self.zeros
        return external_torque_nm(self.model.tcp_jacobian(self.core.out.q), np.array([0, 0, -m * 9.81, 0, 0, 0]))

    def _inertia_diag(self, q: np.ndarray) -> np.ndarray:
        return np.diag(pin.crba(self.model.model, self.model.data, q)).copy()

    def apply(self, command: FriCommand) -> None:
        """Run joint impedance towards ``command`` over the physics steps of one FRI period, the command held."""
        core, o = self.core, self.core.out
        prev = self.command
        dq_cmd = (command.joint_position - prev.joint_position) / self.dt_s \
            if prev is not None and self.p.joint_damping_law == "relative" else self.zeros
        self.command = command
        damping = impedance_damping(self.stiffness, self.p.joint_damping_ratio, self._inertia_diag(o.q))
        for _ in range(self.substeps):
            core.step(joint_impedance_torque(command.torque, command.joint_position, dq_cmd, o.q, o.dq,
                                             self.stiffness, damping) + self.unloaded_torque())
        spring = float(np.max(np.abs(self.stiffness * (command.joint_position - o.q))))
        self.spring_max_nm = max(self.spring_max_nm, spring)

    def hold(self) -> None:
        """The arm on its brakes over the physics steps of one FRI period; the robot has no command."""
        self.command = None
        for _ in range(self.substeps):
            self.core.step_braked()
