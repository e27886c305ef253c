"""Safety shaping of the commanded torques and the task wrench (allocation-light; the per-joint formulas are
compiled, :mod:`.kernels`, and the 1 kHz tick runs them fused in :func:`~.kernels.limit_torque`).

* :class:`TorqueShaper`: absolute joint torque limits and a torque *rate*
  limit (about 1 Nm per ms on the iiwa) on the controller's part of the
  command; the model gravity is outside the rate limit (it changes only as
  fast as the arm moves and must be there from the first tick).
* :func:`joint_margin_torque`: a spring-damper pushing a joint back when it
  comes within ``margin`` of a position limit (zero elsewhere, continuous at
  the margin's edge).
* :func:`clearance_torque`: the nullspace posture that keeps joints out of a
  wider zone before their limits and away from the arm's stretched poses.
* :func:`self_motion_limit`: the clearance scaled so that the self-motion it
  drives in the task's nullspace turns no joint faster than a share of its
  speed limit (near a singular pose a small push turns joints fast), and a
  brake on any self-motion above that share.
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

import math

import numpy as np

from .demand_kernels import largest_share
from .limit_kernels import (
    clearance_into,
    limits_dtype,
    margin_torque_into,
    self_motion_limit_into,
    shape_into,
    shaper_dtype,
    speed_brake_into,
)


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
    rec : the one-element record :func:`~.limit_kernels.limit_torque` takes (:func:`~.limit_kernels.shaper_dtype`)
    tau_max, prev : (n,) [Nm] views of its fields: the absolute limits, the last torque sent less its offset
    clipped_abs, clipped_rate : int
        Ticks on which any joint hit the absolute / rate limit (for status).
    """

    def __init__(self, tau_max_nm: np.ndarray, rate_nm_s: float) -> None:
        tau_max = np.asarray(tau_max_nm, float)
        self.rec = np.zeros(1, shaper_dtype(len(tau_max)))
        self.tau_max: np.ndarray = self.rec["tau_max"][0]
        self.prev: np.ndarray = self.rec["prev"][0]
        self.tau_max[:] = tau_max
        self.rate = float(rate_nm_s)
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
        hit = shape_into(tau_nm, self.prev, self.tau_max, self.rate * dt_s,
                         _NO_OFFSET if offset_nm is None else offset_nm, offset_nm is not None)
        self.count(hit)
        return tau_nm

    def count(self, hit: int) -> None:
        """Count a tick's clipping from :func:`~.kernels.shape_into`'s bit set (1 rate, 2 absolute)."""
        if hit & 1:
            self.clipped_rate += 1
        if hit & 2:
            self.clipped_abs += 1


_NO_OFFSET = np.zeros(0)


def limits_record(q_min: np.ndarray, q_max: np.ndarray, dq_max: np.ndarray, speed_onset_rad_s: np.ndarray,
                  singular: np.ndarray, **settings: float) -> np.ndarray:
    """The limits' record (:func:`~.limit_kernels.limits_dtype`) for an arm of n joints: the (n,) arrays as given
    (``singular`` 1.0 on the joints whose zero stretches the arm), the scalar ``settings`` by their field names
    (every one of them: margin_rad, margin_stiffness_nm_rad, margin_damping_nm_s_rad, speed_brake_1_s, zone_rad,
    singular_rad, clearance_stiffness_nm_rad, clearance_damping_nm_s_rad, clearance_speed_share,
    self_motion_share, self_motion_brake_1_s). ValueError naming a missing or unknown one, or a wrong shape."""
    n = len(q_min)
    dtype = limits_dtype(n)
    rec = np.zeros(1, dtype)
    arrays = {"q_min": q_min, "q_max": q_max, "dq_max": dq_max, "speed_onset_rad_s": speed_onset_rad_s,
              "singular": singular}
    scalars = list(LIMIT_SETTINGS)
    if sorted(settings) != sorted(scalars):
        raise ValueError(f"limits_record: settings must be {scalars}, missing "
                         f"{sorted(set(scalars) - set(settings))}, unknown {sorted(set(settings) - set(scalars))}")
    for name, arr in arrays.items():
        if np.shape(arr) != (n,):
            raise ValueError(f"limits_record: {name} must have shape ({n},), got {np.shape(arr)}")
        rec[name][0] = arr
    for name, value in settings.items():
        rec[name][0] = float(value)
    return rec


def limits_from_settings(arm_limits, p) -> np.ndarray:
    """The controller's limits record (:func:`limits_record`) from the arm's limits ``arm_limits`` (q_min, q_max,
    dq_max (n,), :class:`arm.robot_model.JointLimits`) and the ``[controller.limits]`` settings ``p``
    (:class:`controller.params.LimitParams`): the joint-speed brake from ``joint_speed_share`` of each speed
    limit, the clearance on the ``singular_joints`` (1-based)."""
    n = len(arm_limits.q_min)
    singular = np.zeros(n)
    singular[[j - 1 for j in p.singular_joints if j <= n]] = 1.0
    return limits_record(arm_limits.q_min, arm_limits.q_max, arm_limits.dq_max,
                         p.joint_speed_share * np.asarray(arm_limits.dq_max, float), singular,
                         margin_rad=p.joint_margin_rad, margin_stiffness_nm_rad=p.joint_margin_stiffness_nm_rad,
                         margin_damping_nm_s_rad=p.joint_margin_damping_nm_s_rad,
                         speed_brake_1_s=p.joint_speed_brake_1_s, zone_rad=p.clearance_zone_rad,
                         singular_rad=p.singular_clearance_rad,
                         clearance_stiffness_nm_rad=p.clearance_stiffness_nm_rad,
                         clearance_damping_nm_s_rad=p.clearance_damping_nm_s_rad,
                         clearance_speed_share=p.clearance_speed_share, self_motion_share=p.self_motion_share,
                         self_motion_brake_1_s=p.self_motion_brake_1_s)


#: The scalar settings of :func:`limits_record`, by name.
LIMIT_SETTINGS = ("margin_rad", "margin_stiffness_nm_rad", "margin_damping_nm_s_rad", "speed_brake_1_s", "zone_rad",
                  "singular_rad", "clearance_stiffness_nm_rad", "clearance_damping_nm_s_rad", "clearance_speed_share",
                  "self_motion_share", "self_motion_brake_1_s")
#: Every one at zero: the numpy-facing functions below set the ones they use.
_NO_LIMITS = dict.fromkeys(LIMIT_SETTINGS, 0.0)


def joint_margin_torque(q: np.ndarray, dq: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, margin_rad: float,
                        stiffness_nm_rad: float, damping_nm_s_rad: float) -> np.ndarray:
    """(n,) repulsion [Nm] from the joint position limits.

    Inside ``margin_rad`` of a limit a joint gets ``k * depth`` pushing it
    out, plus ``d * speed`` against motion towards the limit; zero outside
    the margin (continuous at its edge in position, the damping starts with
    the depth so it is continuous too).
    """
    out = np.empty(len(q))
    margin_torque_into(np.asarray(q, float), np.asarray(dq, float), np.asarray(q_min, float), np.asarray(q_max, float),
                       float(margin_rad), float(stiffness_nm_rad), float(damping_nm_s_rad), out)
    return out


def clearance_torque(q: np.ndarray, dq: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, zone_rad: float,
                     singular: np.ndarray, singular_rad: float, stiffness_nm_rad: float,
                     damping_nm_s_rad: float, dq_max: np.ndarray | None = None, speed_share: float = 10.0,
                     out: np.ndarray | None = None) -> np.ndarray:
    """(n,) clearance posture [Nm]: what keeps each joint out of the ``zone_rad`` before its position limits and
    each joint flagged in ``singular`` (n,) out of ``singular_rad`` around zero, where the arm is stretched
    straight at it (the iiwa's A2, A4, A6: two axes in line, one direction of the pad's motion lost).

    Unlike :func:`joint_margin_torque` (the last line, on the full torque, inside a narrower margin) it is
    meant for the task's nullspace (:class:`~.impedance.TaskShaping` ``posture_nm``): the arm moves away from
    the limit or the singular pose by its redundancy only, never by moving the pad. Inside a zone a joint gets
    ``k * depth`` pushing it out plus ``d * speed`` against motion deeper in, scaled by the depth's share of
    the zone (continuous at the zone's edge); faded out while the fastest joint runs at ``speed_share`` - 0.2 to
    ``speed_share`` of its limit ``dq_max`` (n,) [rad/s] (default: never); into ``out`` when given (the 1 kHz
    path)."""
    n = len(q)
    if out is None:
        out = np.empty(n)
    lim = limits_record(np.asarray(q_min, float), np.asarray(q_max, float),
                        np.ones(n) if dq_max is None else np.asarray(dq_max, float), np.zeros(n),
                        np.asarray(singular, float), **{**_NO_LIMITS, "zone_rad": zone_rad,
                                                        "singular_rad": singular_rad,
                                                        "clearance_stiffness_nm_rad": stiffness_nm_rad,
                                                        "clearance_damping_nm_s_rad": damping_nm_s_rad,
                                                        "clearance_speed_share": speed_share})
    clearance_into(np.asarray(q, float), np.asarray(dq, float), lim, out)
    return out


def self_motion_limit(tau_c: np.ndarray, dq: np.ndarray, M: np.ndarray, M_inv: np.ndarray, J: np.ndarray,
                      Lam: np.ndarray, dq_max: np.ndarray, share: float, brake_1_s: float = 0.0) -> float:
    """Scale the clearance ``tau_c`` (n,) [Nm] in place so that the self-motion it drives in the task's nullspace
    turns no joint faster than ``share`` of its limit ``dq_max`` (n,) [rad/s], and add a brake ``brake_1_s`` [1/s]
    on any self-motion above that share; returns the clearance's gain in [0, 1].

    dq (n,) [rad/s]; M, M_inv (n, n) the joint-space inertia and its inverse; J (6, n) the task Jacobian; Lam
    (6, 6) the task inertia (as the law projects with). The formula: :func:`~.limit_kernels.self_motion_limit_into`."""
    tau_c = np.asarray(tau_c)
    n = len(tau_c)
    for name, arr, shape in (("dq", dq, (n,)), ("M", M, (n, n)), ("M_inv", M_inv, (n, n)), ("J", J, (6, n)),
                             ("Lam", Lam, (6, 6)), ("dq_max", dq_max, (n,))):
        if np.shape(arr) != shape:
            raise ValueError(f"self_motion_limit: {name} must have shape {shape}, got {np.shape(arr)}")
    if n < 6 or not share > 0.0 or not brake_1_s >= 0.0:
        raise ValueError(f"self_motion_limit: needs n >= 6 joints, share > 0 and brake_1_s >= 0, got n={n}, "
                         f"share={share!r}, brake_1_s={brake_1_s!r}")
    lim = limits_record(np.zeros(n), np.zeros(n), np.asarray(dq_max, float), np.zeros(n), np.zeros(n),
                        **{**_NO_LIMITS, "self_motion_share": share, "self_motion_brake_1_s": brake_1_s})
    return float(self_motion_limit_into(tau_c, np.asarray(dq, float), np.asarray(M, float),
                                        np.asarray(M_inv, float), np.asarray(J, float), np.asarray(Lam, float), lim))


def saturate_norm(v: np.ndarray, max_norm: float) -> bool:
    """Scale ``v`` in place so that ``|v| <= max_norm``; True if it was clipped."""
    n = float(np.linalg.norm(v))
    if n > max_norm:
        v *= max_norm / n
        return True
    return False


def speed_excess_force(v_m_s: np.ndarray, max_speed_m_s: float, gain_n_s_m: float,
                       out: np.ndarray | None = None) -> np.ndarray:
    """(3,) force [N] braking the pad's speed beyond ``max_speed_m_s`` (zero below it); into ``out`` when given."""
    if out is None:
        out = np.zeros(3)
    vx, vy, vz = float(v_m_s[0]), float(v_m_s[1]), float(v_m_s[2])
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    if speed <= max_speed_m_s:
        out[:] = 0.0
        return out
    f = -gain_n_s_m * (speed - max_speed_m_s) / speed
    out[0], out[1], out[2] = f * vx, f * vy, f * vz
    return out


def joint_speed_brake_torque(dq: np.ndarray, onset_rad_s: np.ndarray, rate_1_s: float, inertia_kg_m2: np.ndarray,
                             out: np.ndarray) -> np.ndarray:
    """(n,) torque [Nm] into ``out``: ``-rate * M_ii * (|dq_i| - onset_i) * sign(dq_i)`` above ``onset_i``, else 0.

    dq : (n,) joint speeds [rad/s]; onset_rad_s : (n,) where braking starts;
    rate_1_s : how fast the excess decays on the joint's own inertia [1/s];
    inertia_kg_m2 : (n,) the diagonal of the joint-space inertia M [kg m^2].
    """
    speed_brake_into(dq, onset_rad_s, float(rate_1_s), inertia_kg_m2, out)
    return out


#: How fast the override's scale may fall [1/s] (its default ``down_rate_1_s``).
OVERRIDE_DOWN_RATE_1_S = 8.0
#: How fast the scale may always fall [1/s], whatever the jerk it adds (the override's job is the joints' speed).
OVERRIDE_JERK_FLOOR_RATE_1_S = 1.0
#: The share of the jerk bound the override's scale changes aim at (the next acceleration is extrapolated).
OVERRIDE_JERK_MARGIN = 0.98
#: How fast the scale climbs back [1/s] to where it was before the robot held (:meth:`SpeedOverride.held`): from a
#: braked arm at rest to a 0.3 m/s stroke in about 90 ms, 3 m/s^2 along the path.
OVERRIDE_RESUME_RATE_1_S = 10.0


class SpeedOverride:
    """Time scaling of the skill so that no joint is asked to move faster than a share of its speed limit.

    Like a robot's speed override, but set by the motion itself: each tick
    the caller reports the joint speeds (n,) [rad/s] that the *unscaled*
    reference would need (:meth:`update`); their largest share of the
    limits is peak-held (it falls by at most ``release_1_s`` per second, so
    a periodic motion gets one steady scale, not one that breathes with each
    stroke; a held share above 1 falls by that share of itself, and is held
    no higher than where the scale reaches ``min_scale``, so a spike of many
    times the limits, a wrist passing a singularity, is released in seconds,
    not minutes); the scale ``s`` in (0, 1] moves towards ``min(1, share / peak)``,
    down by at most ``down_rate_1_s`` and up by at most ``up_rate_1_s`` per second.
    The skill advances by ``s dt``; its velocities are multiplied by ``s``
    and its accelerations by ``s^2`` (the path is unchanged, only slower).

    Parameters
    ----------
    dq_max_rad_s : (n,) joint speed limits [rad/s]. share : the share of them the reference may ask for.
    min_scale : the slowest the skill runs. down_rate_1_s, up_rate_1_s : how fast the scale may change [1/s].
    release_1_s : how fast the held peak demand falls [share/s].
    jerk_bound_m_s3 : the executed in-plane jerk the scale's changes keep to [m/s^3] (inf: no such limit).
    jerk_floor_rate_1_s : how fast the scale may fall whatever the jerk [1/s].
    resume_rate_1_s : how fast the scale climbs back to its value before a hold [1/s] (:meth:`held`).

    The caller may also cap the scale with :attr:`load_cap` (a loop that cannot keep up with the robot slows the
    motion: :func:`load_scale`); the cap is reached through the same rate limits.

    Jerk: the executed acceleration is ``s^2 a(sigma)``, so its jerk is ``s^3 j + 2 s (ds/dt) a``: a scale that
    changes adds to the planned jerk. Given ``jerk_bound_m_s3`` and the skill's unscaled in-plane acceleration
    each tick (``accel`` of :meth:`update`), the scale changes only as fast as keeps the next tick's executed
    jerk within the bound (the next acceleration extrapolated from the last three), but it may always fall at
    ``jerk_floor_rate_1_s`` (the joints' speed comes first; the controller's speed brake is behind it).

    Attributes
    ----------
    scale : float
        The current scale. demand_share : float, the held peak of the unscaled demand over the limits (at most
        ``share / min_scale``).
    slowed_ticks : int
        Ticks with ``scale < 1``. load_limited_ticks : int, ticks on which :attr:`load_cap` set the target.
    load_cap : float
        Upper bound on the target scale, in (0, 1] (1: none).
    jerk_limited_ticks : int
        Ticks on which the jerk bound held the scale's change back.
    """

    def __init__(self, dq_max_rad_s: np.ndarray, share: float, min_scale: float = 0.05,
                 down_rate_1_s: float = OVERRIDE_DOWN_RATE_1_S, up_rate_1_s: float = 0.5, release_1_s: float = 0.5,
                 jerk_bound_m_s3: float = math.inf,
                 jerk_floor_rate_1_s: float = OVERRIDE_JERK_FLOOR_RATE_1_S,
                 resume_rate_1_s: float = OVERRIDE_RESUME_RATE_1_S) -> None:
        self.inv_dq_max = 1.0 / np.asarray(dq_max_rad_s, float)
        self.share = float(share)
        self.min_scale = float(min_scale)
        self.down = float(down_rate_1_s)
        self.up = float(up_rate_1_s)
        self.release = float(release_1_s)
        self.scale = 1.0
        self.demand_share = 0.0
        self.slowed_ticks = 0
        self.load_cap = 1.0
        self.load_limited_ticks = 0
        self.jerk_bound = float(jerk_bound_m_s3) * OVERRIDE_JERK_MARGIN
        self.jerk_floor = float(jerk_floor_rate_1_s)
        self.jerk_limited_ticks = 0
        self.resume = float(resume_rate_1_s)
        self.resume_to = 0.0  #: the scale before the last hold, climbed back to at ``resume`` (0: none)
        self._a_prev = self._a_prev2 = (0.0, 0.0)
        self._n_prev = 0  # accelerations seen (up to 2)

    def reset(self) -> None:
        self.scale = 1.0
        self.demand_share = 0.0
        self.resume_to = 0.0
        self._n_prev = 0

    def held(self, pace: float) -> None:
        """The robot held over the last tick and the skill went at ``pace`` (its step over the tick, a share of
        the tick in [0, scale]: a braked arm 0, one coasting on its last command about the scale): the scale
        drops to that pace (not below ``min_scale``), and climbs back to where it was at ``resume`` per second once
        commands apply again, so a released arm is not asked to be at full speed at once."""
        pace = max(float(pace), self.min_scale)
        if pace < self.scale:
            self.resume_to = max(self.resume_to, self.scale)
            self.scale = pace

    def update(self, demand_rad_s: np.ndarray, dt_s: float, accel: np.ndarray | None = None) -> float:
        """The scale for the next tick, given the joint speeds (n,) the unscaled reference needs now and, for the
        jerk bound, the skill's unscaled in-plane acceleration (2,) [m/s^2] at this tick (None: no jerk limit)."""
        held = self.demand_share
        fall = self.release * dt_s * (held if held > 1.0 else 1.0)  # above the limits: a share of itself per second
        # held no higher than where the scale reaches its floor: beyond it the scale is the same
        r = min(max(largest_share(demand_rad_s, self.inv_dq_max), held - fall), self.share / self.min_scale)
        self.demand_share = r
        target = 1.0 if r <= self.share else max(self.share / r, self.min_scale)
        if self.load_cap < target:
            target = max(self.load_cap, self.min_scale)
            self.load_limited_ticks += 1
        s0 = self.scale
        up = self.up if s0 >= self.resume_to else max(self.up, self.resume)
        s = max(target, s0 - self.down * dt_s) if target < s0 else min(target, s0 + up * dt_s)
        if accel is not None:
            ax, ay = float(accel[0]), float(accel[1])
            if s != s0 and self.jerk_bound < math.inf:
                nx, ny = self._next_accel(ax, ay)
                limited = jerk_limited_scale(s0, s, ax, ay, nx, ny, self.jerk_bound * dt_s)
                if s < s0:
                    limited = min(limited, max(s, s0 - self.jerk_floor * dt_s))
                if limited != s:
                    self.jerk_limited_ticks += 1
                    s = limited
            self._a_prev2 = self._a_prev
            self._a_prev = (ax, ay)
            self._n_prev = min(self._n_prev + 1, 2)
        self.scale = s
        if s >= self.resume_to or s >= target:  # back where it was, or where the motion now wants it
            self.resume_to = 0.0
        if s < 1.0:
            self.slowed_ticks += 1
        return s

    def _next_accel(self, ax: float, ay: float) -> tuple[float, float]:
        """The skill's unscaled acceleration next tick, extrapolated from the last three (quadratic: a planned
        jerk that grows is foreseen), from fewer linearly or held."""
        if self._n_prev >= 2:
            (px, py), (qx, qy) = self._a_prev, self._a_prev2
            return 3.0 * (ax - px) + qx, 3.0 * (ay - py) + qy
        if self._n_prev == 1:
            px, py = self._a_prev
            return 2.0 * ax - px, 2.0 * ay - py
        return ax, ay


def jerk_limited_scale(s0: float, s_wanted: float, ax: float, ay: float, nx: float, ny: float,
                       step_m_s2: float) -> float:
    """The scale between ``s0`` (this tick's) and ``s_wanted`` nearest ``s_wanted`` whose executed acceleration
    next tick, ``s^2 (nx, ny)``, differs from this tick's ``s0^2 (ax, ay)`` by at most ``step_m_s2`` (the jerk
    bound times the tick) [m/s^2]; ``(ax, ay)``, ``(nx, ny)``: the skill's unscaled in-plane acceleration now and
    (predicted) next tick. If none does: the one nearest to doing so (the least jerk on the way). Pure
    arithmetic, no allocation."""
    c2 = s0 * s0
    cx, cy = c2 * ax, c2 * ay
    qa = nx * nx + ny * ny
    if qa < 1e-12:
        return s_wanted  # the acceleration vanishes: the scale does not change the jerk
    # |x n - c|^2 <= step^2 in x = s^2: qa x^2 - 2 qb x + qc <= 0
    qb = nx * cx + ny * cy
    qc = cx * cx + cy * cy - step_m_s2 * step_m_s2
    disc = qb * qb - qa * qc
    if disc < 0.0:
        x_lo = x_hi = qb / qa  # the least jerk
    else:
        root = math.sqrt(disc)
        x_lo, x_hi = (qb - root) / qa, (qb + root) / qa
    seg_lo, seg_hi = (s_wanted, s0) if s_wanted < s0 else (s0, s_wanted)
    x = min(max(s_wanted * s_wanted, max(seg_lo * seg_lo, x_lo)), min(seg_hi * seg_hi, x_hi))
    x = min(max(x, seg_lo * seg_lo), seg_hi * seg_hi)
    return math.sqrt(x)


def load_scale(unanswered_share: float, onset_share: float, limit_share: float, min_scale: float) -> float:
    """The skill's time scale for a loop that leaves ``unanswered_share`` (0-1, filtered) of the robot's states
    unanswered: 1 up to ``onset_share``, falling linearly to ``min_scale`` at ``limit_share`` (where the overload
    watch ends the run) and held there. Slower motion needs smaller torque changes per answer, so the stale
    answers of a starved loop matter less and the force does not spike."""
    if unanswered_share <= onset_share:
        return 1.0
    x = min(1.0, (unanswered_share - onset_share) / max(limit_share - onset_share, 1e-9))
    return 1.0 - x * (1.0 - min_scale)
