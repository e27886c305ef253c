"""A mock arm for tests: seven decoupled joints, no gravity, no contact; a stepped :class:`~robot.port.RobotPort`.

Each joint is an inertia with viscous friction,
``I ddq = tau - d dq`` (semi-implicit Euler at ``dt_s``); ``hold`` brakes
(velocity to zero at once, position kept; or, with ``brake_rad_s2``, each
joint's speed ramped down at that deceleration, as a real brake stops). It
speaks the same ``robot/*`` protocol as the simulator through
:class:`~robot.server.RobotServer`, so a controller or a protocol test
cannot tell it apart, but it needs no physics engine.
"""

from __future__ import annotations

import numpy as np

from interfaces.messages import Capabilities

from .port import Applied, Reading, RobotPort


class MockArm(RobotPort):
    """The mock arm. ``q0_rad`` (7,) start position; ``tau_max_nm`` (7,) limits; ``dt_s`` step [s];
    ``dq_max_rad_s`` (7,) speed limits the server's speed brake watches (None: not declared);
    ``brake_rad_s2`` the brake's deceleration [rad/s^2] (None: it stops every joint within the step)."""

    def __init__(self, q0_rad=None, tau_max_nm=None, dt_s: float = 0.001, inertia_kg_m2: float = 0.5,
                 damping_nm_s_rad: float = 1.0, dq_max_rad_s=None, brake_rad_s2: float | None = None) -> None:
        self.q = np.zeros(7) if q0_rad is None else np.array(q0_rad, float)
        self.dq = np.zeros(7)
        self.tau = np.zeros(7)
        self.dt_s, self.inertia, self.damping = dt_s, inertia_kg_m2, damping_nm_s_rad
        limits = np.full(7, 100.0) if tau_max_nm is None else np.asarray(tau_max_nm, float)
        self.capabilities = Capabilities(True, limits.tolist(), "mock", 1.0 / dt_s)
        self.velocity_limits_rad_s = None if dq_max_rad_s is None else np.asarray(dq_max_rad_s, float)
        self.brake_rad_s2 = brake_rad_s2
        self.steps = 0
        self.holds = 0

    def read(self) -> Reading:
        return Reading(self.q.copy(), self.dq.copy(), self.tau.copy(), np.zeros(6),
                       int(round(self.steps * self.dt_s * 1e9)))

    def write(self, tau_nm: np.ndarray) -> Applied:
        self.tau[:] = tau_nm
        self.dq += self.dt_s * (self.tau - self.damping * self.dq) / self.inertia
        self.q += self.dt_s * self.dq
        self.steps += 1
        return Applied.TORQUES

    def hold(self) -> Applied:
        self.tau[:] = 0.0
        if self.brake_rad_s2 is None:
            self.dq[:] = 0.0
        else:
            self.dq[:] = np.sign(self.dq) * np.maximum(np.abs(self.dq) - self.brake_rad_s2 * self.dt_s, 0.0)
            self.q += self.dt_s * self.dq
        self.steps += 1
        self.holds += 1
        return Applied.HELD

    def held_torque_nm(self) -> np.ndarray:
        """What the last cycle applied: nothing, after a hold (the mock has no gravity)."""
        return self.tau.copy()

    def counters(self) -> dict[str, int]:
        return {"mock_holds": self.holds}
