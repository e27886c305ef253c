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
* :func:`joint_speed_brake_torque`: a damping torque on each joint that
  moves faster than its share of the joint speed limit (so the robot's own
  speed guard, at a higher share, is not what stops a fast motion).
* :class:`SpeedOverride`: slows the skill down (time scaling) where its
  reference would ask a joint for more than a share of its speed limit.
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


def joint_speed_brake_torque(dq: np.ndarray, onset_rad_s: np.ndarray, rate_1_s: float, inertia_kg_m2: np.ndarray,
                             out: np.ndarray) -> np.ndarray:
    """(n,) torque [Nm] into ``out``: ``-rate * M_ii * (|dq_i| - onset_i) * sign(dq_i)`` above ``onset_i``, else 0.

    dq : (n,) joint speeds [rad/s]; onset_rad_s : (n,) where braking starts;
    rate_1_s : how fast the excess decays on the joint's own inertia [1/s];
    inertia_kg_m2 : (n,) the diagonal of the joint-space inertia M [kg m^2].
    """
    np.abs(dq, out=out)
    out -= onset_rad_s
    np.maximum(out, 0.0, out=out)
    out *= np.sign(dq)
    out *= inertia_kg_m2
    out *= -rate_1_s
    return out


class SpeedOverride:
    """Time scaling of the skill so that no joint is asked to move faster than a share of its speed limit.

    Like a robot's speed override, but set by the motion itself: each tick
    the caller reports the joint speeds (n,) [rad/s] that the *unscaled*
    reference would need (:meth:`update`); their largest share of the
    limits is peak-held (it falls by at most ``release_1_s`` per second, so
    a periodic motion gets one steady scale, not one that breathes with each
    stroke); the scale ``s`` in (0, 1] moves towards ``min(1, share / peak)``,
    down by at most ``down_rate_1_s`` and up by at most ``up_rate_1_s`` per second.
    The skill advances by ``s dt``; its velocities are multiplied by ``s``
    and its accelerations by ``s^2`` (the path is unchanged, only slower).

    Parameters
    ----------
    dq_max_rad_s : (n,) joint speed limits [rad/s]. share : the share of them the reference may ask for.
    min_scale : the slowest the skill runs. down_rate_1_s, up_rate_1_s : how fast the scale may change [1/s].
    release_1_s : how fast the held peak demand falls [share/s].

    Attributes
    ----------
    scale : float
        The current scale. demand_share : float, the held peak of the unscaled demand over the limits.
    slowed_ticks : int
        Ticks with ``scale < 1``.
    """

    def __init__(self, dq_max_rad_s: np.ndarray, share: float, min_scale: float = 0.05,
                 down_rate_1_s: float = 8.0, up_rate_1_s: float = 0.5, release_1_s: float = 0.5) -> None:
        self.inv_dq_max = 1.0 / np.asarray(dq_max_rad_s, float)
        self.share = float(share)
        self.min_scale = float(min_scale)
        self.down = float(down_rate_1_s)
        self.up = float(up_rate_1_s)
        self.release = float(release_1_s)
        self.scale = 1.0
        self.demand_share = 0.0
        self.slowed_ticks = 0
        self._ratio = np.zeros_like(self.inv_dq_max)

    def reset(self) -> None:
        self.scale = 1.0
        self.demand_share = 0.0

    def update(self, demand_rad_s: np.ndarray, dt_s: float) -> float:
        """The scale for the next tick, given the joint speeds (n,) the unscaled reference needs now."""
        np.multiply(np.abs(demand_rad_s), self.inv_dq_max, out=self._ratio)
        r = max(float(self._ratio.max()), self.demand_share - self.release * dt_s)
        self.demand_share = r
        target = 1.0 if r <= self.share else max(self.share / r, self.min_scale)
        s = self.scale
        s = max(target, s - self.down * dt_s) if target < s else min(target, s + self.up * dt_s)
        self.scale = s
        if s < 1.0:
            self.slowed_ticks += 1
        return s
