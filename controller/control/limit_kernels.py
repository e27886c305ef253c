"""The torque limits of :mod:`.limits`, compiled (numba, as :mod:`.kernels`, whose docstring says why and how): the
joint-limit repulsion, the joint-speed brake, the torque rate and absolute limits, and :func:`limit_torque`, which
runs them fused in the 1 kHz tick. The numpy-facing API of :mod:`.limits` calls these, so there is one
implementation of each formula."""

from __future__ import annotations

import numba as nb
import numpy as np

_jit = nb.njit(cache=True)  # keeps the GIL: see the docstring of controller.control.kernels
#: The clearance fades out over this much of a joint's speed limit, below its ``speed_share``.
CLEARANCE_FADE_SHARE = 0.2


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
def clearance_into(q: np.ndarray, dq: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, zone_rad: float,
                   singular: np.ndarray, singular_rad: float, stiffness_nm_rad: float, damping_nm_s_rad: float,
                   dq_max: np.ndarray, speed_share: float, out: np.ndarray) -> None:
    """``out`` (n,) [Nm]: the clearance posture of :func:`~.limits.clearance_torque`: a spring of
    ``stiffness_nm_rad`` on each joint's depth into the ``zone_rad`` before a position limit, and on a joint with
    ``singular[i]`` (1.0; else 0.0) on its depth into ``singular_rad`` around zero (the arm stretched at that
    joint), pushed out the way it is (positive at exactly zero); damped by ``damping_nm_s_rad`` on motion
    deeper in, scaled by the depth's share of its zone (zero at the zone's edge: continuous); all of it faded out
    while the fastest joint moves at ``speed_share`` - 0.2 to ``speed_share`` of its limit ``dq_max`` (n,)
    [rad/s] (near a singular pose a small push moves the joints fast: the clearance never drives one)."""
    margin_torque_into(q, dq, q_min, q_max, zone_rad, stiffness_nm_rad, damping_nm_s_rad, out)  # the limits' part
    n = q.shape[0]
    if singular_rad > 0.0:
        for i in range(n):
            depth = max(singular_rad - abs(q[i]), 0.0)
            if singular[i] > 0.0 and depth > 0.0:
                side = 1.0 if q[i] >= 0.0 else -1.0
                out[i] += side * (stiffness_nm_rad * depth - damping_nm_s_rad * depth / singular_rad
                                  * min(side * dq[i], 0.0))
    share = 0.0
    for i in range(n):
        share = max(share, abs(dq[i]) / dq_max[i])
    gain = min(max((speed_share - share) / CLEARANCE_FADE_SHARE, 0.0), 1.0)
    if gain < 1.0:
        for i in range(n):
            out[i] *= gain


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
def limit_torque(tau: np.ndarray, q: np.ndarray, dq: np.ndarray, q_min: np.ndarray, q_max: np.ndarray,
                 margin_rad: float, margin_stiffness: float, margin_damping: float, onset_rad_s: np.ndarray,
                 brake_1_s: float, M: np.ndarray, prev: np.ndarray, tau_max: np.ndarray, step: float,
                 gravity: np.ndarray, use_gravity: bool, work: np.ndarray) -> int:
    """``tau`` (n,) [Nm] plus the joint-limit repulsion and the joint-speed brake (on M's diagonal), then shaped
    (:func:`shape_into`, ``gravity`` outside the rate limit when ``use_gravity``). work : (2, n) scratch.
    Returns :func:`shape_into`'s bit set."""
    n = tau.shape[0]
    margin = work[0]
    brake = work[1]
    margin_torque_into(q, dq, q_min, q_max, margin_rad, margin_stiffness, margin_damping, margin)
    for i in range(n):
        brake[i] = M[i, i]
    speed_brake_into(dq, onset_rad_s, brake_1_s, brake, brake)
    for i in range(n):
        tau[i] += margin[i]
        tau[i] += brake[i]
    return shape_into(tau, prev, tau_max, step, gravity, use_gravity)
