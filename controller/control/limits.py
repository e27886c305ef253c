"""Safety shaping of the commanded torques and the task wrench (pure numpy, allocation-light).

* :class:`TorqueShaper`: absolute joint torque limits and a torque *rate*
  limit (about 1 Nm per ms on the iiwa) on the controller's part of the
  command; the model gravity is outside the rate limit (it changes only as
  fast as the arm moves and must be there from the first tick).
* :func:`joint_margin_torque`: a spring-damper pushing a joint back when it
  comes within ``margin`` of a position limit (zero elsewhere, continuous at
  the margin's edge).
* :func:`saturate_norm`: clip a vector's length (the translational pose
  error, so a far reference cannot command a violent pull).
* :func:`speed_excess_force`: a braking force along the pad's velocity
  when it moves faster than the Cartesian speed limit.
"""

from __future__ import annotations

import numpy as np


class TorqueShaper:
    """Clip torques to ``|tau| <= tau_max`` and ``|tau - tau_prev| <= rate * dt`` per joint.

    Parameters
    ----------
    tau_max_nm : array, shape (n,)
        Absolute joint torque limits [Nm] (from the description and the robot's capabilities).
    rate_nm_s : float
        Largest torque change per second [Nm/s] (1000 = 1 Nm per ms).

    Attributes
    ----------
    clipped_abs, clipped_rate : int
        Ticks on which any joint hit the absolute / rate limit (for status).
    """

    def __init__(self, tau_max_nm: np.ndarray, rate_nm_s: float) -> None:
        self.tau_max = np.asarray(tau_max_nm, float).copy()
        self.rate = float(rate_nm_s)
        self.prev = np.zeros_like(self.tau_max)
        self._lo = np.empty_like(self.tau_max)
        self._hi = np.empty_like(self.tau_max)
        self.clipped_abs = 0
        self.clipped_rate = 0

    def reset(self, tau_nm: np.ndarray | None = None) -> None:
        """Start the rate limit from ``tau_nm`` (default zeros), e.g. after a pause in commands."""
        self.prev[:] = 0.0 if tau_nm is None else np.clip(tau_nm, -self.tau_max, self.tau_max)

    def __call__(self, tau_nm: np.ndarray, dt_s: float, offset_nm: np.ndarray | None = None) -> np.ndarray:
        """Shape ``tau_nm`` (n,) in place and return it.

        offset_nm : (n,) torque outside the rate limit (e.g. the model
        gravity); the rate limit applies to ``tau_nm - offset_nm``, the
        absolute limit to the sum.
        """
        step = self.rate * dt_s
        if offset_nm is not None:
            tau_nm -= offset_nm
        np.subtract(self.prev, step, out=self._lo)
        np.add(self.prev, step, out=self._hi)
        if np.any(tau_nm < self._lo) or np.any(tau_nm > self._hi):
            self.clipped_rate += 1
            np.clip(tau_nm, self._lo, self._hi, out=tau_nm)
        self.prev[:] = tau_nm
        if offset_nm is not None:
            tau_nm += offset_nm
        if np.any(np.abs(tau_nm) > self.tau_max):
            self.clipped_abs += 1
            np.clip(tau_nm, -self.tau_max, self.tau_max, out=tau_nm)
            if offset_nm is not None:  # what was really sent, so the next step starts from it
                np.subtract(tau_nm, offset_nm, out=self.prev)
            else:
                self.prev[:] = tau_nm
        return tau_nm


def joint_margin_torque(q: np.ndarray, dq: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, margin_rad: float,
                        stiffness_nm_rad: float, damping_nm_s_rad: float) -> np.ndarray:
    """(n,) repulsion [Nm] from the joint position limits.

    Inside ``margin_rad`` of a limit a joint gets ``k * depth`` pushing it
    out, plus ``d * speed`` against motion towards the limit; zero outside
    the margin (continuous at its edge in position, the damping starts with
    the depth so it is continuous too).
    """
    lower_depth = np.clip(q_min + margin_rad - q, 0.0, None)
    upper_depth = np.clip(q - (q_max - margin_rad), 0.0, None)
    frac_lo = np.minimum(lower_depth / margin_rad, 1.0)
    frac_hi = np.minimum(upper_depth / margin_rad, 1.0)
    tau = stiffness_nm_rad * (lower_depth - upper_depth)
    tau -= damping_nm_s_rad * (frac_lo * np.minimum(dq, 0.0) + frac_hi * np.maximum(dq, 0.0))
    return tau


def saturate_norm(v: np.ndarray, max_norm: float) -> bool:
    """Scale ``v`` in place so that ``|v| <= max_norm``; True if it was clipped."""
    n = float(np.linalg.norm(v))
    if n > max_norm:
        v *= max_norm / n
        return True
    return False


def speed_excess_force(v_m_s: np.ndarray, max_speed_m_s: float, gain_n_s_m: float) -> np.ndarray:
    """(3,) force [N] braking the pad's speed beyond ``max_speed_m_s`` (zero below it)."""
    speed = float(np.linalg.norm(v_m_s))
    if speed <= max_speed_m_s:
        return np.zeros(3)
    return -gain_n_s_m * (speed - max_speed_m_s) * v_m_s / speed
