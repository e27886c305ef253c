"""The torque limits of :mod:`.limits`, compiled (numba, as :mod:`.kernels`, whose docstring says why and how): the
joint-limit repulsion, the clearance posture and the bound on the self-motion it drives, the joint-speed brake, the
torque rate and absolute limits, and :func:`limit_torque`, which runs them fused in the 1 kHz tick; while the pad
presses on a board, :func:`normal_neutral_into` takes out what the repulsion and the brake would press with. The
numpy-facing API of :mod:`.limits` calls these, so there is one implementation of each formula."""

from __future__ import annotations

import numba as nb
import numpy as np

_jit = nb.njit(cache=True)  # keeps the GIL: see the docstring of controller.control.kernels


def limits_dtype(n: int) -> np.dtype:
    """The torque limits' settings for an arm of ``n`` joints, one record the kernels read by name (made once:
    :func:`~.limits.limits_record`): q_min, q_max (n,) position limits [rad], dq_max (n,) speed limits [rad/s],
    speed_onset_rad_s (n,) where the joint-speed brake starts, singular (n,) 1.0 on the joints whose zero
    stretches the arm; the repulsion's margin_rad [rad], margin_stiffness_nm_rad, margin_damping_nm_s_rad; the
    brake's speed_brake_1_s [1/s]; the clearance's zone_rad, singular_rad [rad], clearance_stiffness_nm_rad,
    clearance_damping_nm_s_rad, clearance_speed_share; the self-motion's self_motion_share and
    self_motion_brake_1_s [1/s]; and work (3, max(n, 6)), the kernels' scratch."""
    v = [(name, "f8", n) for name in ("q_min", "q_max", "dq_max", "speed_onset_rad_s", "singular")]
    f = [(name, "f8") for name in ("margin_rad", "margin_stiffness_nm_rad", "margin_damping_nm_s_rad",
                                   "speed_brake_1_s", "zone_rad", "singular_rad", "clearance_stiffness_nm_rad",
                                   "clearance_damping_nm_s_rad", "clearance_speed_share", "self_motion_share",
                                   "self_motion_brake_1_s")]
    return np.dtype([*v, *f, ("work", "f8", (3, max(n, 6)))], align=True)


def shaper_dtype(n: int) -> np.dtype:
    """The torque shaper's state (:class:`~.limits.TorqueShaper`): prev (n,) the last torque sent less its offset
    [Nm], tau_max (n,) the absolute limits [Nm]."""
    return np.dtype([("prev", "f8", n), ("tau_max", "f8", n)], align=True)
#: The clearance fades out over this much of a joint's speed limit, below its ``speed_share``.
CLEARANCE_FADE_SHARE = 0.2
#: The clearance fades out over this much of a joint's speed limit in its own self-motion, below its share.
SELF_MOTION_FADE_SHARE = 0.1


@_jit
def margin_torque_into(q: np.ndarray, dq: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, margin_rad: float,
                       stiffness_nm_rad: float, damping_nm_s_rad: float, out: np.ndarray) -> None:
    """``out`` (n,) = the joint-limit repulsion of :func:`~.limits.joint_margin_torque`."""
    for i in range(q.shape[0]):
        lo = max(q_min[i] + margin_rad - q[i], 0.0)
        hi = max(q[i] - (q_max[i] - margin_rad), 0.0)
        t = stiffness_nm_rad * (lo - hi)
        t -= damping_nm_s_rad * (min(lo / margin_rad, 1.0) * min(dq[i], 0.0) +
                                 min(hi / margin_rad, 1.0) * max(dq[i], 0.0))
        out[i] = t


@_jit
def clearance_into(q: np.ndarray, dq: np.ndarray, lim: np.ndarray, out: np.ndarray) -> None:
    """``out`` (n,) [Nm]: the clearance posture of :func:`~.limits.clearance_torque` with the settings of ``lim``
    (:func:`limits_dtype`): a spring of ``clearance_stiffness_nm_rad`` on each joint's depth into the ``zone_rad``
    before a position limit, and on a ``singular`` joint on its depth into ``singular_rad`` around zero (the arm
    stretched at that joint), pushed out the way it is (positive at exactly zero); damped by
    ``clearance_damping_nm_s_rad`` on motion deeper in, scaled by the depth's share of its zone (zero at the
    zone's edge: continuous); all of it faded out while the fastest joint moves at ``clearance_speed_share`` - 0.2
    to ``clearance_speed_share`` of its limit ``dq_max`` (near a singular pose a small push moves the joints fast:
    the clearance never drives one)."""
    c = lim[0]
    k, d, singular_rad = c.clearance_stiffness_nm_rad, c.clearance_damping_nm_s_rad, c.singular_rad
    margin_torque_into(q, dq, c.q_min, c.q_max, c.zone_rad, k, d, out)  # the limits' part
    n = q.shape[0]
    if singular_rad > 0.0:
        for i in range(n):
            depth = max(singular_rad - abs(q[i]), 0.0)
            if c.singular[i] > 0.0 and depth > 0.0:
                side = 1.0 if q[i] >= 0.0 else -1.0
                out[i] += side * (k * depth - d * depth / singular_rad * min(side * dq[i], 0.0))
    share = 0.0
    for i in range(n):
        share = max(share, abs(dq[i]) / c.dq_max[i])
    gain = min(max((c.clearance_speed_share - share) / CLEARANCE_FADE_SHARE, 0.0), 1.0)
    if gain < 1.0:
        for i in range(n):
            out[i] *= gain


@_jit
def self_motion_limit_into(tau_c: np.ndarray, dq: np.ndarray, M: np.ndarray, M_inv: np.ndarray, J: np.ndarray,
                           Lam: np.ndarray, lim: np.ndarray) -> float:
    """Bound the self-motion (the arm's motion in the task's nullspace) in the nullspace torques ``tau_c`` (n,)
    [Nm], in place; returns the gain (0-1) left on the clearance ``tau_c`` came in with.

    The nullspace: ``N^T = I - J^T Lam J M^-1`` (M, M_inv (n, n); J (6, n); Lam (6, 6) the task inertia, as the
    law projects with); a self-motion ``v`` has ``J v = 0``, and the task's motion (in the range of ``M^-1 J^T``)
    is M-orthogonal to it. Two bounds, in joint speeds ``dq`` (n,) [rad/s] against ``dq_max`` (n,) [rad/s]:

    * the clearance's own drive: ``tau_c`` accelerates the arm along ``a = M^-1 N^T tau_c``; the joint speeds
      along it now (the M-orthogonal projection of ``dq`` on ``a``, ``s a`` with ``s = a^T M dq / a^T M a``) have
      the largest share ``s max_i |a_i| / dq_max_i`` (signed: positive along the push). ``tau_c`` fades out while
      that share runs from ``share`` - :data:`SELF_MOTION_FADE_SHARE` to ``share``: at rest it holds at full
      strength, and near a singular pose, where a radian of the pushed joint turns others by many (A5 and A7
      near A6 = 0), it moves the arm only as fast as the fastest of them may turn.
    * any self-motion (the rest posture's pull too, which the clearance may have held back): the nullspace part
      of the joint speeds, ``v = dq - M^-1 J^T Lam J dq``, is braked by ``-brake_1_s g M v`` added to ``tau_c``,
      ``g`` rising from 0 to 1 while the largest share ``max_i |v_i| / dq_max_i`` runs from ``share`` to
      ``share`` + :data:`SELF_MOTION_FADE_SHARE` (``M v`` lies in the nullspace: the pad is not braked).

    ``dq_max``, ``share`` (``self_motion_share``) and ``brake_1_s`` (``self_motion_brake_1_s``) are ``lim``'s
    (:func:`limits_dtype`), its ``work`` the scratch; n >= 6."""
    c = lim[0]
    dq_max, share, brake_1_s, work = c.dq_max, c.self_motion_share, c.self_motion_brake_1_s, c.work
    n = tau_c.shape[0]
    a = work[0]
    y = work[1]
    z = work[2]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M_inv[i, j] * tau_c[j]
        a[i] = s  # M^-1 tau_c
    _to_nullspace(a, M_inv, J, Lam, y, z)  # a = M^-1 N^T tau_c
    sigma = 0.0
    for i in range(n):
        sigma = max(sigma, abs(a[i]) / dq_max[i])
    gain = 1.0
    if sigma > 0.0:
        ama = 0.0
        amdq = 0.0
        for i in range(n):
            ma = 0.0
            for j in range(n):
                ma += M[i, j] * a[j]
            ama += a[i] * ma
            amdq += dq[i] * ma
        if ama > 0.0:
            moving = amdq / ama * sigma  # the share of the fastest joint in the self-motion along the push
            gain = min(max((share - moving) / SELF_MOTION_FADE_SHARE, 0.0), 1.0)
            if gain < 1.0:
                for i in range(n):
                    tau_c[i] *= gain
    if brake_1_s > 0.0:
        for i in range(n):
            a[i] = dq[i]
        _to_nullspace(a, M_inv, J, Lam, y, z)  # a = v, the self-motion; z = J^T Lam J dq
        top = 0.0
        for i in range(n):
            top = max(top, abs(a[i]) / dq_max[i])
        g = min(max((top - share) / SELF_MOTION_FADE_SHARE, 0.0), 1.0)
        if g > 0.0:
            for i in range(n):  # M v = M dq - J^T Lam J dq
                s = 0.0
                for j in range(n):
                    s += M[i, j] * dq[j]
                tau_c[i] -= brake_1_s * g * (s - z[i])
    return gain


@_jit
def _to_nullspace(x: np.ndarray, M_inv: np.ndarray, J: np.ndarray, Lam: np.ndarray, b1: np.ndarray,
                  b2: np.ndarray) -> None:
    """``x`` (n,) [joint velocity or acceleration] := ``x - M^-1 J^T Lam J x``, its dynamically consistent
    nullspace part, in place; leaves ``b2`` (n,) = ``J^T Lam J x`` (of the ``x`` given); ``b1`` (>= 6,) scratch."""
    n = x.shape[0]
    for r in range(6):
        s = 0.0
        for j in range(n):
            s += J[r, j] * x[j]
        b2[r] = s  # J x
    for r in range(6):
        s = 0.0
        for j in range(6):
            s += Lam[r, j] * b2[j]
        b1[r] = s  # Lam J x
    for i in range(n):
        s = 0.0
        for r in range(6):
            s += J[r, i] * b1[r]
        b2[i] = s  # J^T Lam J x
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M_inv[i, j] * b2[j]
        x[i] -= s


@_jit
def speed_brake_into(dq: np.ndarray, onset_rad_s: np.ndarray, rate_1_s: float, inertia_kg_m2: np.ndarray,
                     out: np.ndarray) -> None:
    """``out`` (n,) = the joint-speed brake of :func:`~.limits.joint_speed_brake_torque`."""
    for i in range(dq.shape[0]):
        x = max(abs(dq[i]) - onset_rad_s[i], 0.0)
        sign = 1.0 if dq[i] > 0.0 else (-1.0 if dq[i] < 0.0 else 0.0)
        out[i] = -rate_1_s * (x * sign * inertia_kg_m2[i])


@_jit
def shape_into(tau: np.ndarray, prev: np.ndarray, tau_max: np.ndarray, step: float, offset: np.ndarray,
               use_offset: bool) -> int:
    """Rate then absolute limits of :class:`~.limits.TorqueShaper` on ``tau`` (n,) in place; ``prev`` updated.

    Returns a bit set: 1 when the rate limit clipped a joint, 2 when the absolute limit did.
    """
    n = tau.shape[0]
    hit = 0
    for i in range(n):
        t = tau[i] - offset[i] if use_offset else tau[i]
        lo = prev[i] - step
        hi = prev[i] + step
        if t < lo or t > hi:
            hit |= 1
        tau[i] = t
    for i in range(n):
        if hit & 1:
            tau[i] = min(max(tau[i], prev[i] - step), prev[i] + step)
    for i in range(n):
        prev[i] = tau[i]
        if use_offset:
            tau[i] += offset[i]
        if abs(tau[i]) > tau_max[i]:
            hit |= 2
    if hit & 2:
        for i in range(n):
            tau[i] = min(max(tau[i], -tau_max[i]), tau_max[i])
            prev[i] = tau[i] - offset[i] if use_offset else tau[i]
    return hit


@_jit
def normal_neutral_into(q: np.ndarray, dq: np.ndarray, arm: np.ndarray, lim: np.ndarray, axis: np.ndarray,
                        out: np.ndarray) -> float:
    """``out`` (n,) [Nm]: the joint torque that cancels, along the unit ``axis`` (3,) (world), the force on the pad
    of what :func:`limit_torque` adds at ``q``, ``dq`` (n,): the joint-limit repulsion and the joint-speed brake of
    ``lim``. Both act joint by joint, blind to the task; the pad's force on a board along ``axis`` is the force
    regulator's alone, so the part of them it would feel is taken out: with ``f = Lam J M^-1 tau_add`` (the task
    force a joint torque makes, ``arm``: :func:`~.records.arm_dtype` at that state), ``out = -J_v^T axis
    (axis . f_v)`` (adding ``J^T w`` adds exactly ``w`` to it). Returns ``axis . f_v`` [N], the force taken out.
    Scratch: ``lim``'s work rows (:func:`limit_torque` overwrites them)."""
    n = q.shape[0]
    c = lim[0]
    a_ = arm[0]
    J, Lam, M_inv = a_.J, a_.Lam, a_.M_inv
    add = c.work[0]
    brake = c.work[1]
    margin_torque_into(q, dq, c.q_min, c.q_max, c.margin_rad, c.margin_stiffness_nm_rad, c.margin_damping_nm_s_rad,
                       add)
    for i in range(n):
        brake[i] = a_.M[i, i]
    speed_brake_into(dq, c.speed_onset_rad_s, c.speed_brake_1_s, brake, brake)
    for i in range(n):
        add[i] += brake[i]
    y = c.work[1]  # M^-1 tau_add
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M_inv[i, j] * add[j]
        y[i] = s
    jy = c.work[2]  # J M^-1 tau_add (6,)
    for r in range(6):
        s = 0.0
        for j in range(n):
            s += J[r, j] * y[j]
        jy[r] = s
    f_n = 0.0
    for r in range(3):
        s = 0.0
        for k in range(6):
            s += Lam[r, k] * jy[k]
        f_n += axis[r] * s
    for i in range(n):
        s = 0.0
        for r in range(3):
            s += J[r, i] * axis[r]
        out[i] = -s * f_n
    return f_n


@_jit
def limit_torque(tau: np.ndarray, q: np.ndarray, dq: np.ndarray, M: np.ndarray, gravity: np.ndarray,
                 use_gravity: bool, lim: np.ndarray, shaper: np.ndarray, step: float) -> int:
    """``tau`` (n,) [Nm] plus the joint-limit repulsion and the joint-speed brake (on M's (n, n) diagonal) of
    ``lim`` (:func:`limits_dtype`), then shaped by ``shaper`` (:func:`shaper_dtype`) with a rate limit of
    ``step`` [Nm] (:func:`shape_into`; ``gravity`` (n,) [Nm] outside the rate limit when ``use_gravity``).
    Returns :func:`shape_into`'s bit set."""
    n = tau.shape[0]
    c = lim[0]
    margin = c.work[0]
    brake = c.work[1]
    margin_torque_into(q, dq, c.q_min, c.q_max, c.margin_rad, c.margin_stiffness_nm_rad, c.margin_damping_nm_s_rad,
                       margin)
    for i in range(n):
        brake[i] = M[i, i]
    speed_brake_into(dq, c.speed_onset_rad_s, c.speed_brake_1_s, brake, brake)
    for i in range(n):
        tau[i] += margin[i]
        tau[i] += brake[i]
    sh = shaper[0]
    return shape_into(tau, sh.prev, sh.tau_max, step, gravity, use_gravity)
