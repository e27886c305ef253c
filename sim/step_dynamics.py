"""The arm's dynamics at a physics step's start, and the contact wrench the arm's motion over the step implies.

PyBullet steps ``M (dq' - dq) / dt = tau_pb - h + J^T f`` (semi-implicit
Euler), so the pad's contact wrench is

    f = (J J^T + eps I)^-1 J (M (dq' - dq) / dt + h - tau_pb)

by least squares (``J`` is 6 x n), with ``M``, ``h`` and ``J`` taken at the
step's start. Why the sim reads the wrench from the motion and not from the
contact points: :mod:`sim.robot`.
"""

from __future__ import annotations

import numpy as np
import pybullet as pb

from .world import World


class StepDynamics:
    """What a physics step starts from, and the solver's scratch (``n`` joints, world axes, SI units).

    M : (n, n) PyBullet's joint-space mass matrix [kg m^2]; h : (n,) ``C dq + g`` [Nm]; q0 : the joint positions
    (n floats) [rad]; dq0 : (n,) the joint speeds [rad/s]; J : (6, n) the pad centre's Jacobian (linear rows
    first), taken only when the pad was loaded (else None); tau_pb : (n,) the torques PyBullet is given for the
    step [Nm]; torques_known : whether ``tau_pb`` is what PyBullet applies (not after a brake), so the motion
    gives the wrench. robot, tcp_link, client : the arm's body, its TCP link and the physics client;
    zeros : n zeros (PyBullet's argument); dt_s : the physics step [s].
    """

    __slots__ = ("client", "robot", "tcp_link", "zeros", "dt_s", "M", "h", "q0", "dq0", "J", "tau_pb",
                 "torques_known", "_y", "_ddq", "_JJt", "_eps6")

    def __init__(self, world: World, zeros: list[float], dt_s: float) -> None:
        n = len(zeros)
        self.client = world.client
        self.robot = world.robot
        self.tcp_link = world.tcp_link
        self.zeros = zeros
        self.dt_s = dt_s
        self.M = np.zeros((n, n))
        self.h = np.zeros(n)
        self.q0: list[float] = zeros
        self.dq0 = np.zeros(n)
        self.J: np.ndarray | None = None
        self.tau_pb = np.zeros(n)
        self.torques_known = False
        self._y = np.zeros(n)
        self._ddq = np.zeros(n)
        self._JJt = np.zeros((6, 6))
        self._eps6 = 1e-9 * np.eye(6)  # J J^T regularised: finite at a singular pose

    def take(self, q: np.ndarray, dq: np.ndarray, loaded: bool) -> None:
        """PyBullet's ``M`` and ``h = C dq + g`` at joint positions ``q`` (n,) [rad] and speeds ``dq`` (n,) [rad/s],
        and the pad's Jacobian when it is ``loaded`` (a contact or an external wrench on it)."""
        robot, c = self.robot, self.client
        self.q0 = ql = q.tolist()
        self.dq0[:] = dq
        self.M[:] = pb.calculateMassMatrix(robot, ql, physicsClientId=c)
        self.h[:] = pb.calculateInverseDynamics(robot, ql, dq.tolist(), self.zeros, physicsClientId=c)
        self.J = self.jacobian(ql) if loaded else None

    def jacobian(self, q: list[float]) -> np.ndarray:
        """(6, n) the pad centre's Jacobian at ``q``, world axes (the TCP link's inertial frame is its link frame,
        about which the wrench is taken)."""
        lin, ang = pb.calculateJacobian(self.robot, self.tcp_link, [0.0, 0.0, 0.0], q, self.zeros, self.zeros,
                                        physicsClientId=self.client)
        return np.array(lin + ang)

    def wrench_into(self, wrench: np.ndarray, dq: np.ndarray, external: np.ndarray) -> None:
        """Replace ``wrench`` (6,) [N, Nm] by the wrench the step's motion (speeds ``dq`` (n,) [rad/s] after it)
        says the pad felt, less ``external`` (6,), the one someone else put on it; left as it is unless
        :attr:`torques_known`."""
        if not self.torques_known:
            return
        J = self.J if self.J is not None else self.jacobian(self.q0)
        y, ddq, JJt = self._y, self._ddq, self._JJt
        np.subtract(dq, self.dq0, out=ddq)
        ddq /= self.dt_s
        np.matmul(self.M, ddq, out=y)
        y += self.h
        y -= self.tau_pb
        np.matmul(J, J.T, out=JJt)
        JJt += self._eps6
        wrench[:] = np.linalg.solve(JJt, J @ y)
        wrench -= external
