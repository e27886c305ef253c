"""The hold of an armed adapter whose controller falls silent: the pad stopped in the board's plane, its press kept.

Why not the measured pose with a zero overlay: the robot's joint spring-damper stops each joint on its own
(``D (dc/dt - dq)`` per joint, LBRServer.java's joint impedance), and the pad's acceleration that makes,
``J M^-1 (-D dq)``, has a part along the pad's axis and a rotation: a pad sliding on the board at 0.3 m/s has the
board take that part, its leading edge pressed in (a recorded real-time run: 10 -> 47 N, the pad tilting 0.1 ->
0.85 deg over an 80 ms hold), and with the press gone the pad drifts off the board, so the first commands after
the hold strike it (5 -> 30 N in 10 ms).

:class:`ContactBrake` instead asks the joints for ``tau = J^T (Lambda a + f_press) - b N^T dq``: ``a`` (6,) the
pad's acceleration that decays its in-plane velocity over ``tau_lin_s`` and its angular velocity over
``tau_rot_s``, nothing along the pad's axis while it presses; ``Lambda = (J M^-1 J^T)^-1`` the pad's
operational-space inertia, so the joints' braking makes no pad acceleration into the board for the contact to
take; ``f_press`` the normal contact force measured when the hold began (kept over ``press_min_n``: below, the
pad is taken for free and its motion along its axis braked too), ramped to zero over ``ramp_s`` (the disarm's
zero overlay then finds it gone); ``N^T = I - J^T Lambda J M^-1`` the dynamically consistent null space, damped
by ``b`` [Nm s/rad]; the torque clipped to the joints' limits. The adapter hands ``tau`` to
:meth:`~robot.lbr.compensation.JointSpring.command`, which takes the stack's spring off it. J: the pad's (6, 7)
Jacobian, world axes, linear rows first; M: the joint inertia (7, 7).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel


class ContactBrake:
    """The braking torque (7,) [Nm] of a hold (module docstring); :meth:`start` at the hold's first cycle."""

    def __init__(self, model: RobotModel, ramp_s: float, press_min_n: float, tau_lin_s: float = 0.1,
                 tau_rot_s: float = 0.05, null_damping: float = 2.0) -> None:
        self.model = model
        self.ramp_s = ramp_s
        self.press_min_n = press_min_n
        self.tau_lin_s = tau_lin_s
        self.tau_rot_s = tau_rot_s
        self.null_damping = null_damping
        self._press_n = 0.0  # the normal force measured at the hold's start, along the pad's axis [N]
        self._t0_ns = 0
        self._J = np.zeros((6, 7))  # the pad's Jacobian, its axis (world), Lambda, N^T at the hold's start
        self._n = np.zeros(3)
        self._lam: np.ndarray = np.zeros((6, 6))
        self._null_t = np.zeros((7, 7))

    def start(self, q: np.ndarray, wrench_world: np.ndarray, t_ns: int) -> None:
        """The hold begins at robot time ``t_ns`` with the pad's measured ``wrench_world`` (6,) [N, Nm] (the
        environment's force on the pad, world axes) at joints ``q`` (7,) [rad]. J, Lambda, N and the pad's axis are
        taken here, once: a hold is at most ``hold_timeout_s`` of a decelerating arm (0.36 rad/s stopped over
        0.1 s moves a joint 0.02 rad), and the server's loop answers every state of a 1 kHz robot."""
        m = self.model
        self._J = m.tcp_jacobian(q)
        self._n = m.tcp_pose(q)[1][:, 2]
        M = pin.crba(m.model, m.data, np.asarray(q, float))
        M = np.triu(M) + np.triu(M, 1).T
        JMinv = np.linalg.solve(M, self._J.T).T  # J M^-1 (6, 7)
        self._lam = np.linalg.inv(JMinv @ self._J.T)
        self._null_t = np.eye(len(q)) - self._J.T @ self._lam @ JMinv
        press = -float(np.asarray(wrench_world[:3], float) @ self._n)  # the pad's axis points into the board
        self._press_n = press if press > self.press_min_n else 0.0  # a press, never a pull nor the model's error
        self._t0_ns = t_ns

    def torque(self, dq: np.ndarray, t_ns: int) -> np.ndarray:
        """(7,) [Nm] at joint velocities ``dq`` (7,) [rad/s], robot time ``t_ns``."""
        J, n = self._J, self._n
        v = J @ dq
        a = np.empty(6)
        a[:3] = -(v[:3] - (v[:3] @ n) * n) / self.tau_lin_s
        if self._press_n == 0.0:  # no press kept: the pad free, its motion along its axis braked too
            a[:3] -= (v[:3] @ n) * n / self.tau_lin_s
        a[3:] = -v[3:] / self.tau_rot_s
        f = self._lam @ a
        share = max(0.0, 1.0 - (t_ns - self._t0_ns) * 1e-9 / self.ramp_s) if self.ramp_s > 0 else 0.0
        f[:3] += self._press_n * share * n
        tau_max = self.model.limits.tau_max
        return np.clip(J.T @ f - self.null_damping * (self._null_t @ dq), -tau_max, tau_max)
