"""The control law in numpy, one expression per equation: the oracle the compiled law is tested against
(``tests/test_kernels.py``) and the baseline ``bench/bench_controller.py`` times it against.

This is the formulation the controller ran before its arithmetic was compiled
(``controller/control/kernels.py``); ``controller/control/impedance.py`` has the equations.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def numpy_kinematics(model, q, dq) -> dict:
    """The arm's terms at (q, dq), as :class:`~controller.control.impedance.Kinematics` names them."""
    m, d, f = model.model, model.data, model.tcp_id
    pin.computeAllTerms(m, d, q, dq)
    M = np.triu(d.M) + np.triu(d.M, 1).T
    M_inv = pin.computeMinverse(m, d, q).copy()
    M_inv = np.triu(M_inv) + np.triu(M_inv, 1).T
    pin.updateFramePlacements(m, d)
    J = pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED)
    pin.forwardKinematics(m, d, q, dq, np.zeros(model.nq))
    drift = pin.getFrameClassicalAcceleration(m, d, f, pin.LOCAL_WORLD_ALIGNED).vector.copy()
    return dict(M=M, M_inv=M_inv, J=J, p=d.oMf[f].translation.copy(), R=d.oMf[f].rotation.copy(), twist=J @ dq,
                nle=d.nle.copy(), g=d.g.copy(), drift=drift, Lambda=np.linalg.inv(J @ M_inv @ J.T + 1e-6 * np.eye(6)))


def _clip(v, limit) -> None:
    n = np.linalg.norm(v)
    if n > limit:
        v *= limit / n


def numpy_law(k, q, dq, ref, params, q_rest, add_gravity, shaping, modes):
    """(tau, F, e, de, tau_null, slack) of the impedance law with the terms ``k`` of :func:`numpy_kinematics`.

    ``slack`` bounds, for tau and tau_null, the rounding the null-space projection can leave [N m]: it
    subtracts from tau0 a term of the same size, through Lambda, whose inverse (J M^-1 J^T) reaches a
    condition number of 1e8 near a singular pose; two formulations agree there only to
    eps * cond * size, not to rounding of the (smaller) difference.
    """
    e = np.concatenate([ref.p_m - k["p"], pin.log3(ref.R @ k["R"].T)])
    _clip(e[:3], shaping.max_position_error_m)
    _clip(e[3:], shaping.max_rotation_error_rad)
    de = ref.twist - k["twist"]
    a = ref.accel - k["drift"]
    n = shaping.force_axis
    if n is not None:
        for v in (e, de, a):
            v[:3] -= (v[:3] @ n) * n
    Lam = k["Lambda"]
    F = modes.B @ (modes.k * (modes.B.T @ e) + modes.d * (modes.B.T @ de)) + Lam @ a
    if n is not None:
        F[:3] -= (shaping.press_n + float(n @ Lam[:3, :3] @ n) * shaping.normal_damping_1_s
                  * float(k["twist"][:3] @ n)) * n
    if shaping.extra_force_n is not None:
        F[:3] += shaping.extra_force_n
    kn = params.nullspace_stiffness_nm_rad
    tau0 = k["M"] @ (kn * (q_rest - q) - 2.0 * np.sqrt(kn) * dq)
    if shaping.posture_nm is not None:
        tau0 = tau0 + shaping.posture_nm
    projected = k["J"].T @ (Lam @ (k["J"] @ (k["M_inv"] @ tau0)))
    tau_null = tau0 - projected
    task = k["J"].T @ F
    tau = task + tau_null + k["nle"]
    if not add_gravity:
        tau -= k["g"]
    cond = np.linalg.cond(k["J"] @ k["M_inv"] @ k["J"].T + 1e-6 * np.eye(6))
    bound = 4.0 * np.finfo(float).eps * cond * max(np.abs(tau0).max(), np.abs(projected).max())
    return tau, F, e, de, tau_null, {"tau": bound, "tau_null": bound}


def numpy_modes(Lam, K, zeta, cap):
    """Task stiffness and damping (6, 6) of the modes of ``Lam`` on ``K``, capped at ``cap`` [rad/s]."""
    s = np.sqrt(K)
    m, U = np.linalg.eigh(Lam / np.outer(s, s))
    m = np.clip(m, 1e-12, None)
    k = np.minimum(1.0, cap * cap * m)
    B = s[:, None] * U
    return (B * k) @ B.T, (B * (2.0 * zeta * np.sqrt(k * m))) @ B.T  # K, D: independent of the eigenvectors' signs
