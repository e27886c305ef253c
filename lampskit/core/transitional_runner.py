"""Step API of the transitional MP: :class:`TransitionalRunner`, ruckig style (docs/transitional_mp.md, section 6)."""

from __future__ import annotations

import math
import time

import numpy as np

from lampskit.core.transitional import TransitionalMP, TransitionStatus
from lampskit.core.transitional_maths import N_TABLE
from lampskit.core.transitional_plan import plan_transition


class TransitionalRunner:
    """Ruckig-style stepper: build once, then :meth:`update` once per control cycle.

    After each call, :attr:`position_m`, :attr:`velocity_m_s`,
    :attr:`acceleration_m_s2` (arrays, shape (n_dims,); updated in place:
    copy to keep), :attr:`time_s` and :attr:`calculation_duration_us` (wall
    time of the last update) describe the reference and its cost. From
    ``t >= T`` on, :meth:`update`
    returns ``FINISHED`` and the state follows the goal's constant-acceleration
    extrapolation (continuous with the transition), so the caller can hand
    over to the next MP ``overrun_s`` into its motion.

    Parameters
    ----------
    mp, start, goal, duration_s, forcing_transform
        As :func:`plan_transition` (which validates them and may raise
        :class:`PlanningError`).
    """

    def __init__(
        self,
        mp: TransitionalMP,
        start: object,
        goal: object,
        duration_s: float,
        forcing_transform: np.ndarray | None = None,
    ) -> None:
        self.plan = plan_transition(mp, start, goal, duration_s, forcing_transform)
        p = self.plan
        self._T = p.duration_s
        self._n = mp.n_dims
        self._goal = p.goal
        self._a = 0.0 if math.isinf(p.sigma_s) else -1.0 / p.sigma_s**2
        self._scale = np.array([[1.0], [1.0 / self._T], [1.0 / self._T**2]])
        self._hermite = mp.table
        self._m = mp.table.shape[1] // 12
        self._coefficients = p.coefficients
        self._state = p.start.copy()
        self.position_m, self.velocity_m_s, self.acceleration_m_s2 = self._state[0], self._state[1], self._state[2]
        self.time_s = 0.0
        self.calculation_duration_us = 0.0
        self.status = TransitionStatus.WORKING

    @property
    def duration_s(self) -> float:
        return self._T

    @property
    def finished(self) -> bool:
        return self.status == TransitionStatus.FINISHED

    @property
    def overrun_s(self) -> float:
        """Time past the end of the transition [s] (0 while working)."""
        return max(0.0, self.time_s - self._T)

    def update(self, dt_s: float) -> TransitionStatus:
        """Advance by ``dt_s`` [s] (> 0, finite); never raises."""
        t0 = time.perf_counter_ns()
        status = self._advance(dt_s)
        self.calculation_duration_us = (time.perf_counter_ns() - t0) * 1e-3
        return status

    def _advance(self, dt_s: float) -> TransitionStatus:
        if not (dt_s > 0.0 and dt_s < math.inf):
            return TransitionStatus.ERROR_INVALID_INPUT
        t = self.time_s + dt_s
        self.time_s = t
        T = self._T
        u = t - T
        g = self._goal
        st = self._state
        if u >= -1e-9 * T:
            st[0] = g[0] + u * g[1] + 0.5 * u * u * g[2]
            st[1] = g[1] + u * g[2]
            st[2] = g[2]
            self.status = TransitionStatus.FINISHED
            return self.status
        z = t / T * N_TABLE
        i = int(z)
        if i >= N_TABLE:
            i = N_TABLE - 1
        a = z - i
        a2 = a * a
        a3 = a2 * a
        w = np.array((2 * a3 - 3 * a2 + 1, a3 - 2 * a2 + a, -2 * a3 + 3 * a2, a3 - a2))
        e = (w @ self._hermite[i].reshape(4, -1)).reshape(3, self._m) @ self._coefficients
        # crossing target, inline version of crossing_target_coefficients for one time
        ca = self._a
        w0 = math.exp(0.5 * ca * u * u)
        w1 = ca * u * w0
        w2 = (ca + ca * ca * u * u) * w0
        coef = np.array(
            ((1.0, w0 * u, 0.5 * w0 * u * u),
             (0.0, w1 * u + w0, 0.5 * w1 * u * u + w0 * u),
             (0.0, w2 * u + 2.0 * w1, 0.5 * w2 * u * u + 2.0 * w1 * u + w0))
        )
        np.add(coef @ g, e * self._scale, out=st)
        return self.status
