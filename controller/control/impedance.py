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
    tau_0  = M (K_n (q_rest - q) - 2 sqrt(K_n) dq)  posture
             + tau_c                               clearance (TaskShaping.posture_nm)

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
does). The clearance tau_c (:func:`~.limit_kernels.clearance_into`: joints
kept from their limits and from the arm's singular poses) is a posture
term too, so it moves the arm only where the pad does not have to move.
Gravity is added only when the robot does not compensate it itself.
Orientation errors use the rotation matrix logarithm, which takes the
shorter way and has no quaternion sign ambiguity.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from interfaces.robot_model import RobotModel

from .kernels import impedance_into, kinematics_terms, task_modes_into
from .params import ImpedanceParams
from .records import arm_dtype, new_record, view

#: Regularisation of the task inertia's inverse: Lambda = (J M^-1 J^T + eps I)^-1 stays finite at singularities.
LAMBDA_EPS = 1e-6


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
    arrays are preallocated and refreshed in place (keep a copy to compare
    ticks); the arithmetic after Pinocchio is one compiled call
    (:func:`~.kernels.kinematics_terms`).
    """

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        #: the terms as one record (:func:`~.records.arm_dtype`), what the kernels take; the attributes view it
        self.rec = new_record(arm_dtype(model.nq))
        rec = self.rec
        self.M = view(rec, "M")
        self.M_inv = view(rec, "M_inv")
        self.J = view(rec, "J")
        self.Lambda = view(rec, "Lam")
        self.p = view(rec, "p")
        self.R = view(rec, "R")
        self.R[:] = np.eye(3)
        self.twist = view(rec, "twist")
        self.nle = view(rec, "nle")
        self.g = view(rec, "g")
        self.drift = view(rec, "drift")

    def update(self, q: np.ndarray, dq: np.ndarray) -> Kinematics:
        m, d, f = self.model.model, self.model.data, self.model.tcp_id
        # M, nle, g, joint Jacobians, placements, and the joint accelerations at zero joint acceleration
        pin.computeAllTerms(m, d, q, dq)
        M_inv = pin.computeMinverse(m, d, q)
        oMf = pin.updateFramePlacement(m, d, f)
        # dJ dq: the pad's classical acceleration at zero joint acceleration (computeAllTerms' forward pass)
        acc = pin.getFrameClassicalAcceleration(m, d, f, pin.LOCAL_WORLD_ALIGNED)
        pin_out = (d.M, M_inv, pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED), oMf.translation,
                   oMf.rotation, d.nle, d.g, acc.vector)
        if not kinematics_terms(pin_out, dq, LAMBDA_EPS, self.rec):
            # only with non-finite inputs (the matrix is SPD by construction): what numpy makes of them
            self.Lambda[:] = np.linalg.inv(self.J @ self.M_inv @ self.J.T + LAMBDA_EPS * np.eye(6))
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
    _work: np.ndarray = field(default=None, repr=False)  # the kernel's scratch, (7, max(n, 6))
    _axis: np.ndarray = field(default_factory=lambda: np.zeros(3), repr=False)  # shaping's vectors, copied
    _extra: np.ndarray = field(default_factory=lambda: np.zeros(3), repr=False)
    _posture: np.ndarray = field(default_factory=lambda: np.zeros(7), repr=False)


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
    [N] (world; e.g. a speed-limit brake). posture_nm : (n,) joint torques
    [Nm] added to the posture, projected into the task's nullspace with it.
    """

    force_axis: np.ndarray | None = None
    press_n: float = 0.0
    normal_damping_1_s: float = 0.0
    stiffness_scale: float = 1.0
    max_position_error_m: float = np.inf
    max_rotation_error_rad: float = np.inf
    extra_force_n: np.ndarray | None = None
    posture_nm: np.ndarray | None = None


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


def task_modes(Lam: np.ndarray, K: np.ndarray, zeta: float, max_omega_rad_s: float,
               out: TaskModes | None = None) -> TaskModes:
    """The modes of task mass ``Lam`` (6, 6) on diagonal stiffness ``K`` (6,), capped and damped.

    With S = diag(sqrt(K)) and ``S^-1 Lam S^-1 = U diag(m) U^T``, B = S U:
    mode i has mass m_i and unit stiffness (natural frequency 1/sqrt(m_i)).
    A mode faster than ``max_omega_rad_s`` gets stiffness ``max_omega^2 m_i``
    (it then rings at exactly the cap); every mode gets damping
    ``2 zeta sqrt(k_i m_i)``. Without a capped mode K is ``diag(K)`` exactly.
    out : modes to overwrite (the 1 kHz path) instead of new arrays. One compiled call
    (:func:`~.kernels.task_modes_into`).
    """
    if out is None:
        out = TaskModes(np.zeros((6, 6)), np.zeros(6), np.zeros(6))
    task_modes_into(np.ascontiguousarray(Lam, float), np.ascontiguousarray(K, float), float(zeta),
                    float(max_omega_rad_s), out.B, out.k, out.d)
    return out


def impedance_torque(model: RobotModel, q: np.ndarray, dq: np.ndarray, ref: Reference, params: ImpedanceParams,
                     q_rest: np.ndarray, add_gravity: bool, shaping: TaskShaping = _PLAIN,
                     kin: Kinematics | None = None, modes: TaskModes | None = None,
                     out: ImpedanceTerms | None = None) -> ImpedanceTerms:
    """Joint torques (7,) [Nm] of the impedance law at state ``q``, ``dq`` (see the module docstring).

    With ``shaping.force_axis = n`` the translational error, twist error
    and reference acceleration lose their component along n, which instead
    gets ``-press_n`` of force and a damping ``-Lambda_nn c v_n``.
    kin : the arm's :class:`Kinematics` already updated at (q, dq) this
    tick (computed here when None). modes : :func:`task_modes` of this
    stiffness (with ``shaping.stiffness_scale``) on a recent Lambda (the
    modes change slowly with the pose; computed here when None). out : the
    terms of an earlier call (:func:`new_terms`) to write into instead of
    allocating (the 1 kHz path); its ``p_m``, ``R``, ``twist``, ``Lambda``
    and ``J`` are then ``kin``'s own arrays. The arithmetic is one compiled
    call (:func:`~.kernels.impedance_into`).
    """
    if kin is None:
        kin = Kinematics(model).update(q, dq)
    if modes is None:
        modes = task_modes(kin.Lambda, task_stiffness(params, shaping.stiffness_scale), params.damping_factor,
                           params.max_mode_frequency_rad_s)
    if out is None:
        out = new_terms(kin)
        out.p_m, out.R, out.twist, out.Lambda, out.J = (kin.p.copy(), kin.R.copy(), kin.twist.copy(),
                                                       kin.Lambda.copy(), kin.J.copy())
    axis, extra = shaping.force_axis, shaping.extra_force_n
    if axis is not None:  # into the terms' own buffers: the kernel then always sees the same array types
        out._axis[:] = axis
    if extra is not None:
        out._extra[:] = extra
    posture = shaping.posture_nm
    if posture is not None:
        out._posture[:] = posture
    impedance_into(kin.M, kin.M_inv, kin.J, kin.Lambda, kin.twist, kin.drift, kin.nle, kin.g, kin.p, kin.R,
                   ref.p_m, ref.R, ref.twist, ref.accel,
                   out._axis, axis is not None, float(shaping.press_n),
                   float(shaping.normal_damping_1_s), float(shaping.max_position_error_m),
                   float(shaping.max_rotation_error_rad), out._extra, extra is not None, out._posture,
                   posture is not None,
                   modes.B, modes.k, modes.d, float(params.nullspace_stiffness_nm_rad), q_rest, q, dq,
                   bool(add_gravity),
                   out.tau_nm, out.wrench_task, out.pose_error, out.twist_error, out.tau_nullspace, out._work)
    return out


def new_terms(kin: Kinematics) -> ImpedanceTerms:
    """Preallocated :class:`ImpedanceTerms` for :func:`impedance_torque`'s ``out`` (pose arrays: ``kin``'s)."""
    n = kin.model.nq
    return ImpedanceTerms(np.zeros(n), np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(n), kin.p, kin.R,
                          kin.twist, kin.Lambda, kin.J, np.zeros((7, max(n, 6))), _posture=np.zeros(n))
