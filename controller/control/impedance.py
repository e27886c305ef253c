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

import numpy as np
import pinocchio as pin

from arm.robot_model import RobotModel

from .kernels import impedance_into, kinematics_terms, task_modes_into
from .params import ImpedanceParams
from .records import MODES_DTYPE, REFERENCE_DTYPE, RecordViews, arm_dtype, law_dtype, new_record, terms_dtype, view

#: Regularisation of the task inertia's inverse: Lambda = (J M^-1 J^T + eps I)^-1 stays finite at singularities.
LAMBDA_EPS = 1e-6


class Reference(RecordViews):
    """Where the pad should be: position ``p_m`` (3,) [m], orientation ``R`` (3, 3), ``twist`` (6,) [m/s, rad/s],
    acceleration ``accel`` (6,) [m/s^2, rad/s^2], world axes (zero and identity when not given).

    The arrays view one record (``rec``, :data:`~.records.REFERENCE_DTYPE`), what the kernels take: write into
    them (``ref.p_m[:] = ...``; ``ref.p_m = ...`` copies too).
    """

    _views = {"p_m": "p", "R": "R", "twist": "twist", "accel": "accel"}
    p_m: np.ndarray
    R: np.ndarray
    twist: np.ndarray
    accel: np.ndarray

    def __init__(self, p_m: np.ndarray | None = None, R: np.ndarray | None = None, twist: np.ndarray | None = None,
                 accel: np.ndarray | None = None) -> None:
        self._bind(REFERENCE_DTYPE)
        self.R[:] = np.eye(3) if R is None else R
        for mine, given in ((self.p_m, p_m), (self.twist, twist), (self.accel, accel)):
            if given is not None:
                mine[:] = given


class Kinematics(RecordViews):
    """Everything the law needs about the arm at (q, dq), from one Pinocchio pass per tick.

    Call :meth:`update`; then ``M`` (7, 7) inertia, ``M_inv``, ``J`` (6, 7)
    pad Jacobian (world-aligned, linear rows first), ``p`` (3,) [m], ``R``
    (3, 3), ``twist`` (6,) = J dq, ``nle`` (7,) = C dq + g, ``g`` (7,)
    gravity, ``drift`` (6,) = dJ dq, ``Lambda`` (6, 6) task inertia. The
    arrays are preallocated and refreshed in place (keep a copy to compare
    ticks); the arithmetic after Pinocchio is one compiled call
    (:func:`~.kernels.kinematics_terms`).
    """

    _views = {"M": "M", "M_inv": "M_inv", "J": "J", "Lambda": "Lam", "p": "p", "R": "R", "twist": "twist",
              "nle": "nle", "g": "g", "drift": "drift"}
    M: np.ndarray
    M_inv: np.ndarray
    J: np.ndarray
    Lambda: np.ndarray
    p: np.ndarray
    R: np.ndarray
    twist: np.ndarray
    nle: np.ndarray
    g: np.ndarray
    drift: np.ndarray

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self._bind(arm_dtype(model.nq))  # the terms as one record, what the kernels take; the attributes view it
        self.R[:] = np.eye(3)

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


class ImpedanceTerms(RecordViews):
    """The parts of one evaluation, for logs and tests (all world axes): ``tau_nm`` (n,) [Nm], ``wrench_task``
    (6,) task wrench, ``pose_error`` (6,), ``twist_error`` (6,), ``tau_nullspace`` (n,) [Nm] (views of the
    record ``rec``, :func:`~.records.terms_dtype`, that the kernel writes); and the arm's ``p_m``, ``R``,
    ``twist``, ``Lambda``, ``J`` at that state (:class:`Kinematics`' own arrays when made by :func:`new_terms`)."""

    _views = {"tau_nm": "tau", "wrench_task": "F", "pose_error": "e", "twist_error": "de",
              "tau_nullspace": "tau_null"}
    tau_nm: np.ndarray
    wrench_task: np.ndarray
    pose_error: np.ndarray
    twist_error: np.ndarray
    tau_nullspace: np.ndarray

    def __init__(self, kin: Kinematics) -> None:
        self._bind(terms_dtype(kin.model.nq))
        self.p_m, self.R, self.twist, self.Lambda, self.J = kin.p, kin.R, kin.twist, kin.Lambda, kin.J


def pose_error(p_ref: np.ndarray, R_ref: np.ndarray, p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(6,) ``[p_ref - p ; log(R_ref R^T)]``: the world-frame rotation vector taking R to R_ref."""
    return np.concatenate([p_ref - p, pin.log3(R_ref @ R.T)])


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
    [N] (world; e.g. a speed-limit brake). posture_nm : (n_joints,) joint torques
    [Nm] added to the posture, projected into the task's nullspace with it.

    All but ``stiffness_scale`` live in one record (``rec``, :func:`~.records.law_dtype`), what the kernel
    takes: setting a vector copies it in (a getter returns the record's view, or None when not set).
    """

    def __init__(self, force_axis: np.ndarray | None = None, press_n: float = 0.0, normal_damping_1_s: float = 0.0,
                 stiffness_scale: float = 1.0, max_position_error_m: float = np.inf,
                 max_rotation_error_rad: float = np.inf, extra_force_n: np.ndarray | None = None,
                 posture_nm: np.ndarray | None = None, n_joints: int = 7) -> None:
        self.rec = new_record(law_dtype(n_joints))
        rec = self.rec
        self._axis, self._extra, self._posture = view(rec, "force_axis"), view(rec, "extra_force_n"), \
            view(rec, "posture_nm")
        self._use = {name: rec[name] for name in ("use_axis", "use_extra", "use_posture")}  # (1,) views
        self._has = {"use_axis": False, "use_extra": False, "use_posture": False}  # the flags, read without numpy
        self._press = rec["press_n"]
        self.stiffness_scale = stiffness_scale
        rec["normal_damping_1_s"] = normal_damping_1_s
        rec["max_position_error_m"] = max_position_error_m
        rec["max_rotation_error_rad"] = max_rotation_error_rad
        self.force_axis = force_axis
        self.press_n = press_n
        self.extra_force_n = extra_force_n
        self.posture_nm = posture_nm

    def _set(self, flag: str, mine: np.ndarray, given: np.ndarray | None) -> None:
        if given is not None:
            if np.shape(given) != mine.shape:
                raise ValueError(f"TaskShaping: {flag[4:]} of shape {np.shape(given)}, expected {mine.shape}")
            mine[:] = given
        has = given is not None
        if has is not self._has[flag]:  # the record's flag written only when it changes (a numpy write per tick)
            self._use[flag][0] = has
            self._has[flag] = has

    @property
    def force_axis(self) -> np.ndarray | None:
        return self._axis if self._has["use_axis"] else None

    @force_axis.setter
    def force_axis(self, axis: np.ndarray | None) -> None:
        self._set("use_axis", self._axis, axis)

    @property
    def extra_force_n(self) -> np.ndarray | None:
        return self._extra if self._has["use_extra"] else None

    @extra_force_n.setter
    def extra_force_n(self, force: np.ndarray | None) -> None:
        self._set("use_extra", self._extra, force)

    @property
    def posture_nm(self) -> np.ndarray | None:
        return self._posture if self._has["use_posture"] else None

    @posture_nm.setter
    def posture_nm(self, tau: np.ndarray | None) -> None:
        self._set("use_posture", self._posture, tau)

    def posture_in_record(self, tau: np.ndarray) -> np.ndarray:
        """Use ``tau`` (n,) [Nm] as :attr:`posture_nm` and return the record's own array that holds it: written
        there in place every tick, the compiled law reads it without a copy."""
        self.posture_nm = tau
        return self._posture

    @property
    def press_n(self) -> float:
        return float(self._press[0])

    @press_n.setter
    def press_n(self, f: float) -> None:
        self._press[0] = f

    @property
    def normal_damping_1_s(self) -> float:
        return float(self.rec["normal_damping_1_s"][0])

    @property
    def max_position_error_m(self) -> float:
        return float(self.rec["max_position_error_m"][0])

    @property
    def max_rotation_error_rad(self) -> float:
        return float(self.rec["max_rotation_error_rad"][0])


_PLAIN = TaskShaping()


class TaskModes(RecordViews):
    """Stiffness and damping of the task as modes: ``K = B diag(k) B^T``, ``D = B diag(d) B^T``.

    B (6, 6): the mode shapes, scaled so that ``B^-1 Lambda B^-T`` is
    diagonal too (the modal masses); k (6,), d (6,): modal stiffness and
    damping (multiply by the 6-vectors in ``B^T`` coordinates).
    The arrays view one record (``rec``, :data:`~.records.MODES_DTYPE`), what the kernels take.
    """

    _views = {"B": "B", "k": "k", "d": "d"}
    B: np.ndarray
    k: np.ndarray
    d: np.ndarray

    def __init__(self, B: np.ndarray | None = None, k: np.ndarray | None = None, d: np.ndarray | None = None) -> None:
        self._bind(MODES_DTYPE)
        for mine, given in ((self.B, B), (self.k, k), (self.d, d)):
            if given is not None:
                mine[:] = given

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
        out = TaskModes()
    task_modes_into(np.ascontiguousarray(Lam, float), np.ascontiguousarray(K, float), float(zeta),
                    float(max_omega_rad_s), out.rec)
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
    if len(shaping._posture) != len(kin.g):
        raise ValueError(f"TaskShaping for {len(shaping._posture)} joints, the arm has {len(kin.g)}: "
                         f"TaskShaping(n_joints={len(kin.g)})")
    impedance_into(kin.rec, ref.rec, modes.rec, shaping.rec, (q, dq, q_rest),
                   float(params.nullspace_stiffness_nm_rad), bool(add_gravity), out.rec)
    return out


def new_terms(kin: Kinematics) -> ImpedanceTerms:
    """Preallocated :class:`ImpedanceTerms` for :func:`impedance_torque`'s ``out`` (pose arrays: ``kin``'s)."""
    return ImpedanceTerms(kin)
