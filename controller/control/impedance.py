"""Cartesian impedance with task-space inertia, reference feed-forward and a consistent nullspace.

For the pad centre x (position p, orientation R) with Jacobian J (6, 7),
joint-space inertia M, task-space inertia Lambda = (J M^-1 J^T)^-1 and
dynamically consistent generalised inverse Jbar = M^-1 J^T Lambda::

    e      = [p_ref - p ; log(R_ref R^T)]          pose error, world axes
    de     = v_ref - J dq                          twist error
    F      = Lambda (a_ref - dJ dq) + K e + D de   (6,) task wrench
    D      = 2 zeta per mode of Lambda on K        (see :func:`task_modes`)
    tau    = J^T F + N^T tau_0 + C(q, dq) dq [+ g(q)]
    N^T    = I - J^T Jbar^T                        consistent nullspace projector
    tau_0  = M (K_n (q_rest - q) - 2 sqrt(K_n) dq) posture

The damping is designed on the modes of the task-space mass on the
stiffness (double diagonalisation): each mode is damped with ratio zeta.
Damping each axis with Lambda's diagonal instead over-damps the modes
whose mass is much smaller than that diagonal (the wrist: 4x critical at
the start pose), and a damper that strong on a light joint is unstable
with two periods of loop delay. No mode is stiffer than
``max_mode_frequency_rad_s`` either (the wrist's spin on K_r alone would
be at ~350 rad/s): the loop's delay margin is then known, whatever the pose.
The feed-forward Lambda (a_ref - dJ dq) cancels the inertia of the
tracked motion (dJ dq is the pad's acceleration at zero joint acceleration,
the velocity-product part); without it a 1 Hz circle of 5 cm radius is
tracked 3-4x worse at the same stiffness. The projector keeps
the posture term from pushing the pad (a plain pseudo-inverse projector
does). Gravity is added only when the robot does not compensate it itself.
Orientation errors use the rotation matrix logarithm, which takes the
shorter way and has no quaternion sign ambiguity.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from interfaces.robot_model import RobotModel

from .params import ImpedanceParams


@dataclass
class Reference:
    """Where the pad should be: position (3,) [m], orientation (3, 3), twist (6,) [m/s, rad/s], acceleration (6,)."""

    p_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    twist: np.ndarray = field(default_factory=lambda: np.zeros(6))
    accel: np.ndarray = field(default_factory=lambda: np.zeros(6))


class Kinematics:
    """Everything the law needs about the arm at (q, dq), from one Pinocchio pass per tick.

    Call :meth:`update`; then ``M`` (7, 7) inertia, ``M_inv``, ``J`` (6, 7)
    pad Jacobian (world-aligned, linear rows first), ``p`` (3,) [m], ``R``
    (3, 3), ``twist`` (6,) = J dq, ``nle`` (7,) = C dq + g, ``g`` (7,)
    gravity, ``drift`` (6,) = dJ dq, ``Lambda`` (6, 6) task inertia. The
    arrays are refreshed in place.
    """

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self._lower = np.tril_indices(model.nq, -1)
        self._zeros = np.zeros(model.nq)
        self._eps = 1e-6 * np.eye(6)
        self.M = self.M_inv = self.J = self.Lambda = None
        self.p = np.zeros(3)
        self.R = np.eye(3)
        self.twist = np.zeros(6)
        self.nle = np.zeros(model.nq)
        self.g = np.zeros(model.nq)
        self.drift = np.zeros(6)

    def update(self, q: np.ndarray, dq: np.ndarray) -> "Kinematics":
        m, d, f = self.model.model, self.model.data, self.model.tcp_id
        pin.computeAllTerms(m, d, q, dq)  # M, nle, g, joint Jacobians, placements
        M = d.M.copy()
        M[self._lower] = M.T[self._lower]  # older Pinocchio fills the upper triangle only
        self.M = M
        M_inv = pin.computeMinverse(m, d, q).copy()
        M_inv[self._lower] = M_inv.T[self._lower]
        self.M_inv = M_inv
        pin.updateFramePlacements(m, d)
        oMf = d.oMf[f]
        self.p[:] = oMf.translation
        self.R[:] = oMf.rotation
        self.J = J = pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED)
        np.matmul(J, dq, out=self.twist)
        self.nle[:] = d.nle
        self.g[:] = d.g
        pin.forwardKinematics(m, d, q, dq, self._zeros)
        acc = pin.getFrameClassicalAcceleration(m, d, f, pin.LOCAL_WORLD_ALIGNED)
        self.drift[:3] = acc.linear
        self.drift[3:] = acc.angular
        self.Lambda = np.linalg.inv(J @ M_inv @ J.T + self._eps)
        return self


@dataclass
class ImpedanceTerms:
    """The parts of one evaluation, for logs and tests (all world axes)."""

    tau_nm: np.ndarray
    wrench_task: np.ndarray
    pose_error: np.ndarray
    twist_error: np.ndarray
    tau_nullspace: np.ndarray
    p_m: np.ndarray
    R: np.ndarray
    twist: np.ndarray
    Lambda: np.ndarray
    J: np.ndarray


def pose_error(p_ref: np.ndarray, R_ref: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(6,) ``[p_ref - p ; log(R_ref R^T)]``: the world-frame rotation vector taking R to R_ref."""
    return np.concatenate([p_ref - p, pin.log3(R_ref @ R.T)])


@dataclass
class TaskShaping:
    """Per-tick modifiers of the impedance law (defaults: the plain law).

    force_axis : (3,) unit vector (world) along which the force is
    regulated instead of the position (the board's outward normal); None =
    full pose impedance. press_n : force [N] the pad exerts along
    ``-force_axis`` (into the board). normal_damping_1_s : damping of the
    pad's speed along ``force_axis`` [1/s], scaled by the task inertia
    along it. stiffness_scale : factor on K (and D by sqrt) for gain ramps.
    max_position_error_m, max_rotation_error_rad : the pose error is
    clipped to these lengths. extra_force_n : (3,) more force on the pad
    [N] (world; e.g. a speed-limit brake).
    """

    force_axis: np.ndarray | None = None
    press_n: float = 0.0
    normal_damping_1_s: float = 0.0
    stiffness_scale: float = 1.0
    max_position_error_m: float = np.inf
    max_rotation_error_rad: float = np.inf
    extra_force_n: np.ndarray | None = None


_PLAIN = TaskShaping()


@dataclass
class TaskModes:
    """Stiffness and damping of the task as modes: ``K = B diag(k) B^T``, ``D = B diag(d) B^T``.

    B (6, 6): the mode shapes, scaled so that ``B^-1 Lambda B^-T`` is
    diagonal too (the modal masses); k (6,), d (6,): modal stiffness and
    damping (multiply by the 6-vectors in ``B^T`` coordinates).
    """

    B: np.ndarray
    k: np.ndarray
    d: np.ndarray

    def wrench(self, e: np.ndarray, de: np.ndarray) -> np.ndarray:
        """K e + D de (6,) for pose error ``e`` (6,) and twist error ``de`` (6,), without forming K or D."""
        B = self.B
        return B @ (self.k * (B.T @ e) + self.d * (B.T @ de))

    def stiffness(self) -> np.ndarray:
        """K (6, 6)."""
        return (self.B * self.k) @ self.B.T

    def damping(self) -> np.ndarray:
        """D (6, 6)."""
        return (self.B * self.d) @ self.B.T


def task_stiffness(params: ImpedanceParams, scale: float = 1.0) -> np.ndarray:
    """(6,) diagonal task stiffness [N/m x3, Nm/rad x3] times ``scale``."""
    return scale * np.array([params.stiffness_n_m] * 3 + [params.stiffness_nm_rad] * 3)


def task_modes(Lam: np.ndarray, K: np.ndarray, zeta: float, max_omega_rad_s: float) -> TaskModes:
    """The modes of task mass ``Lam`` (6, 6) on diagonal stiffness ``K`` (6,), capped and damped.

    With S = diag(sqrt(K)) and ``S^-1 Lam S^-1 = U diag(m) U^T``, B = S U:
    mode i has mass m_i and unit stiffness (natural frequency 1/sqrt(m_i)).
    A mode faster than ``max_omega_rad_s`` gets stiffness ``max_omega^2 m_i``
    (it then rings at exactly the cap); every mode gets damping
    ``2 zeta sqrt(k_i m_i)``. Without a capped mode K is ``diag(K)`` exactly.
    """
    s = np.sqrt(K)
    m, U = np.linalg.eigh(Lam / np.outer(s, s))
    m = np.clip(m, 1e-12, None)
    k = np.minimum(1.0, max_omega_rad_s * max_omega_rad_s * m)
    return TaskModes(s[:, None] * U, k, 2.0 * zeta * np.sqrt(k * m))


def _clip_norm(v: np.ndarray, limit: float) -> None:
    n = float(np.linalg.norm(v))
    if n > limit:
        v *= limit / n


def impedance_torque(model: RobotModel, q: np.ndarray, dq: np.ndarray, ref: Reference, params: ImpedanceParams,
                     q_rest: np.ndarray, add_gravity: bool, shaping: TaskShaping = _PLAIN,
                     kin: Kinematics | None = None, modes: TaskModes | None = None) -> ImpedanceTerms:
    """Joint torques (7,) [Nm] of the impedance law at state ``q``, ``dq`` (see the module docstring).

    With ``shaping.force_axis = n`` the translational error, twist error
    and reference acceleration lose their component along n, which instead
    gets ``-press_n`` of force and a damping ``-Lambda_nn c v_n``.
    kin : the arm's :class:`Kinematics` already updated at (q, dq) this
    tick (computed here when None). modes : :func:`task_modes` of this
    stiffness (with ``shaping.stiffness_scale``) on a recent Lambda (the
    modes change slowly with the pose; computed here when None).
    """
    if kin is None:
        kin = Kinematics(model).update(q, dq)
    M, M_inv, J, Lam, twist = kin.M, kin.M_inv, kin.J, kin.Lambda, kin.twist
    e = pose_error(ref.p_m, ref.R, kin.p, kin.R)
    _clip_norm(e[:3], shaping.max_position_error_m)
    _clip_norm(e[3:], shaping.max_rotation_error_rad)
    de = ref.twist - twist
    a = ref.accel - kin.drift
    n = shaping.force_axis
    if n is not None:
        for v in (e, de, a):
            v[:3] -= (v[:3] @ n) * n
    if modes is None:
        modes = task_modes(Lam, task_stiffness(params, shaping.stiffness_scale), params.damping_factor,
                           params.max_mode_frequency_rad_s)
    F = modes.wrench(e, de) + Lam @ a
    if n is not None:
        lam_n = float(n @ Lam[:3, :3] @ n)
        F[:3] -= (shaping.press_n + lam_n * shaping.normal_damping_1_s * float(twist[:3] @ n)) * n
    if shaping.extra_force_n is not None:
        F[:3] += shaping.extra_force_n
    kn = params.nullspace_stiffness_nm_rad
    tau0 = M @ (kn * (q_rest - q) - 2.0 * np.sqrt(kn) * dq)
    # N^T tau0 = tau0 - J^T Jbar^T tau0 with Jbar^T = Lambda J M^-1
    tau_null = tau0 - J.T @ (Lam @ (J @ (M_inv @ tau0)))
    tau = J.T @ F + tau_null + kin.nle
    if not add_gravity:
        tau -= kin.g
    return ImpedanceTerms(tau, F, e, de, tau_null, kin.p.copy(), kin.R.copy(), twist.copy(), Lam, J)
