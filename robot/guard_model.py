"""The robot side's view of its arm through the description: the pad's motion and one cycle of a command ahead.

:class:`ToolMotion` wraps a :class:`~arm.robot_model.RobotModel`
(Pinocchio) with its own data (one instance per thread, as the model asks):
the pad centre's position, axis and linear velocity from ``q``, ``dq`` (one
forward pass with velocities, about 6 us), and the joint speeds one cycle of a
command leaves (:meth:`ToolMotion.predict`: the articulated-body algorithm
with the rotor inertia, about 7 us). The robot side has the description the
controller has (the sim is built from it; the lbr adapter already uses it for
the wrench), so it needs nothing from the controller to know how fast the pad
moves or what a command will do.
"""

from __future__ import annotations

import numpy as np


class ToolMotion:
    """The pad's motion (world frame, SI units) for one arm. ``gravity_compensated``: the robot adds gravity to
    every command itself (the prediction adds it too).

    Attributes (buffers, refreshed by :meth:`update`): p (3,) pad centre [m]; R (3, 3) its orientation (columns
    x, y along the felt, z into what it presses on); v, w (3,) its linear [m/s] and angular [rad/s] velocity;
    dq_next (7,) the last prediction [rad/s].
    """

    def __init__(self, model, gravity_compensated: bool) -> None:
        import pinocchio as pin  # only robot sides with a description pay for the import

        self._pin = pin
        self._model = model.model
        self._data = self._model.createData()
        self._frame = model.tcp_id
        self._ref = pin.LOCAL_WORLD_ALIGNED
        self.gravity_compensated = gravity_compensated
        self.p = np.zeros(3)
        self.R = np.eye(3)
        self.v = np.zeros(3)
        self.w = np.zeros(3)
        self.dq_next = np.zeros(self._model.nv)
        self._tau = np.zeros(self._model.nv)

    def update(self, q: np.ndarray, dq: np.ndarray) -> None:
        """The pad at ``q``, ``dq`` (7,) [rad, rad/s]: :attr:`p`, :attr:`R`, :attr:`v`, :attr:`w`."""
        pin, model, data = self._pin, self._model, self._data
        pin.forwardKinematics(model, data, q, dq)
        oMf = pin.updateFramePlacement(model, data, self._frame)
        self.p[:] = oMf.translation
        self.R[:] = oMf.rotation
        twist = pin.getFrameVelocity(model, data, self._frame, self._ref)
        self.v[:] = twist.linear
        self.w[:] = twist.angular

    def twist(self, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pad's linear [m/s] and angular [rad/s] velocity (3,), (3,) at ``q``, ``dq`` (7,) (fresh arrays; the
        attributes are left alone)."""
        pin = self._pin
        pin.forwardKinematics(self._model, self._data, q, dq)
        twist = pin.getFrameVelocity(self._model, self._data, self._frame, self._ref)
        return twist.linear, twist.angular

    def predict(self, q: np.ndarray, dq: np.ndarray, tau_nm: np.ndarray, dt_s: float) -> np.ndarray:
        """The joint speeds (7,) [rad/s] after ``tau_nm`` (7,) [Nm] held ``dt_s`` [s] from ``q``, ``dq`` (7,):
        ``dq + dt M(q)^-1 (tau (+ g(q)) - C(q, dq) dq - g(q))`` (:attr:`dq_next`, reused). Friction and contact are
        left out: both only slow the arm, so the prediction errs on the safe side."""
        pin, tau = self._pin, self._tau
        tau[:] = tau_nm
        if self.gravity_compensated:
            tau += pin.computeGeneralizedGravity(self._model, self._data, q)
        ddq = pin.aba(self._model, self._data, q, dq, tau)
        np.multiply(ddq, dt_s, out=self.dq_next)
        self.dq_next += dq
        return self.dq_next
