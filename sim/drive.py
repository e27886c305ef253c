"""The simulated drives: from the motor torques to the torques PyBullet applies, with rotor inertia and friction.

PyBullet has no armature and integrates (semi-implicit Euler, step dt)

    M(q) ddq = tau_pb - h(q, dq) + J^T f

with h = C dq + g and f the contact wrench on the pad. The arm with
reflected rotor inertia Ia and joint friction tau_f(dq)
(:mod:`arm.joint_dynamics`) obeys instead

    (M + Ia) ddq = tau - tau_f - h + J^T f.

Both give the same ddq when

    tau_pb = h_hat + M a,    (M + Ia + dt D) a = tau - tau_f(dq) - h_hat

with h_hat = h - J^T f_prev (the contact wrench of the step before stands
for the one to come) and D = dtau_f/ddq (diagonal). The dt D term makes the
friction linearly implicit, tau_f evaluated at the step's end speed
dq + a dt: Coulomb friction is steep near rest (Fc / v_eps, e.g. 0.14 Nm
over 2 mrad/s on A7, whose link inertia is 1e-3 kg m^2), and an explicit
step of it oscillates. Brakes bypass this (PyBullet's velocity motors).

The arithmetic is one compiled call (numba, as the controller's kernels:
a dozen numpy calls on 7-vectors cost more in overhead than in flops);
:func:`drive_torque` is its checked form.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from arm.joint_dynamics import JointDynamics
from lampskit.spd import cholesky_lower_in_place, cholesky_solve_in_place

_jit = nb.njit(cache=True)


def drives_record(joints: JointDynamics, dt_s: float) -> np.ndarray:
    """The drives' record for :func:`drive_torque_into`, made once: a one-element structured array with fields fv,
    fc (n,) viscous [Nm s/rad] and Coulomb [Nm] friction, v_eps the Coulomb smoothing speed [rad/s], armature (n,)
    [kg m^2], dt_s the physics step [s], and the kernel's scratch L (n, n), a (n,)."""
    n = len(joints.armature_kg_m2)
    rec = np.zeros(1, np.dtype([("fv", "f8", n), ("fc", "f8", n), ("armature", "f8", n), ("v_eps", "f8"),
                                ("dt_s", "f8"), ("L", "f8", (n, n)), ("a", "f8", n)], align=True))
    r = rec[0]
    r["fv"], r["fc"], r["armature"] = joints.viscous_nm_s_rad, joints.coulomb_nm, joints.armature_kg_m2
    r["v_eps"], r["dt_s"] = joints.coulomb_velocity_rad_s, dt_s
    return rec


def drive_torque(tau: np.ndarray, dq: np.ndarray, M: np.ndarray, h_hat: np.ndarray, joints: JointDynamics,
                 dt_s: float) -> np.ndarray:
    """(n,) torques [Nm] for PyBullet that give the arm with armature and friction its acceleration.

    tau : (n,) motor torques [Nm]; dq : (n,) joint speeds [rad/s]; M : (n, n) PyBullet's inertia [kg m^2];
    h_hat : (n,) C dq + g - J^T f_prev [Nm]; joints : armature and friction; dt_s : physics step [s].
    Raises ValueError for wrong shapes, a non-positive step or an M + Ia that is not positive definite.
    """
    tau, dq, h_hat = (np.asarray(v, float) for v in (tau, dq, h_hat))
    M = np.asarray(M, float)
    n = tau.shape[0]
    if M.shape != (n, n) or dq.shape != (n,) or h_hat.shape != (n,) or len(joints.armature_kg_m2) != n:
        raise ValueError(f"shapes: tau, dq, h_hat ({n},), M ({n}, {n}) and {n} joints; got dq {dq.shape}, "
                         f"h_hat {h_hat.shape}, M {M.shape}, {len(joints.armature_kg_m2)} joints")
    if not dt_s > 0.0:
        raise ValueError(f"dt_s must be positive, got {dt_s}")
    out = np.empty(n)
    if not drive_torque_into(tau, dq, M, h_hat, drives_record(joints, float(dt_s)), out):
        raise ValueError("M + diag(armature) is not positive definite")
    return out


@_jit
def drive_torque_into(tau: np.ndarray, dq: np.ndarray, M: np.ndarray, h_hat: np.ndarray, drives: np.ndarray,
                      out: np.ndarray) -> bool:
    """Unchecked :func:`drive_torque` into ``out`` (n,), the drives and the scratch in ``drives``
    (:func:`drives_record`; the 1 kHz path). Returns False (``out`` undefined) when M + Ia + dt D is not
    positive definite."""
    d = drives[0]
    fv, fc, v_eps, armature, dt_s, L, a = d.fv, d.fc, d.v_eps, d.armature, d.dt_s, d.L, d.a
    n = tau.shape[0]
    for i in range(n):  # friction (the tanh law of arm.joint_dynamics) and its slope on the diagonal
        t = math.tanh(dq[i] / v_eps)
        a[i] = tau[i] - (fc[i] * t + fv[i] * dq[i]) - h_hat[i]
        L[i, i] = M[i, i] + armature[i] + dt_s * (fv[i] + fc[i] / v_eps * (1.0 - t * t))
    for i in range(n):  # M + Ia + dt D: M's lower triangle, the diagonal above
        for j in range(i):
            L[i, j] = M[i, j]
    if not cholesky_lower_in_place(L):
        return False
    cholesky_solve_in_place(L, a)
    for i in range(n):
        s = h_hat[i]
        for k in range(n):
            s += M[i, k] * a[k]
        out[i] = s
    return True
