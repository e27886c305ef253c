"""The control law's arithmetic, compiled (numba): one call per stage of the 1 kHz tick.

The law works on 6- and 7-vectors and 6x6 / 7x7 matrices. As numpy
expressions each of its ~60 small operations costs 0.5-5 us of call and
allocation overhead for a few dozen flops, which was most of a tick
(Pinocchio's own algorithms take about 7 us). Here each stage is one
compiled function that writes into arrays the caller preallocated:

* :func:`kinematics_terms`: M and M^-1 symmetrised from their upper
  triangles, the pad twist ``J dq`` and the task inertia
  ``Lambda = (J M^-1 J^T + eps I)^-1`` (Cholesky, the matrix is SPD);
* :func:`impedance_into`: the impedance law of :mod:`.impedance`
  (pose error with the rotation logarithm, force axis, modal stiffness and
  damping, feed-forward, consistent nullspace posture, gravity);
* :func:`~.limit_kernels.limit_torque`: joint-limit repulsion, joint-speed brake, then the
  torque rate and absolute limits of :class:`~.limits.TorqueShaper`;
* the pieces they use (:func:`log3_into`, :func:`~.limit_kernels.margin_torque_into`,
  :func:`~.limit_kernels.speed_brake_into`, :func:`~.limit_kernels.shape_into`) are compiled functions
  too, and the numpy-facing API of :mod:`.limits` calls them, so there is
  one implementation of each formula;
* :func:`~.demand_kernels.joint_demand_into` and :func:`~.demand_kernels.largest_share`: the joint
  speeds the reference asks for, for the speed override.

The torque limits are in :mod:`.limit_kernels`, the override's demand in
:mod:`.demand_kernels`, compiled the same way (this docstring holds for them).

``fastmath`` stays off: results equal the numpy formulation to rounding
(tests compare them). ``cache=True`` keeps the machine code beside this file
(``__pycache__``, or ``NUMBA_CACHE_DIR``), so a machine compiles them once;
a :class:`~controller.core.ControllerCore` calls each kernel with the array
types its tick will pass when it is made, so no tick waits for the compiler
(``tests/test_kernels.py`` checks that a closed loop adds no signature).
The kernels keep the GIL (no ``nogil``): each takes microseconds, and a
1 kHz thread that let go of the GIL that often would hand it to whichever
Python thread waits (Zenoh callbacks, the planner) and wait up to a switch
interval to get it back. (Whether it did could not be told apart from the
run-to-run spread of the real-time cell on two shared cores.)
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from lampskit.spd import cholesky_inverse_into, cholesky_lower_in_place

_jit = nb.njit(cache=True)  # keeps the GIL: see the module docstring


@_jit
def spd_inverse_into(A: np.ndarray, out: np.ndarray, L: np.ndarray) -> bool:
    """``out = A^-1`` for a symmetric positive definite ``A`` (n, n) by Cholesky (:mod:`lampskit.spd`); ``L`` (n, n)
    is scratch.

    Returns False (``out`` undefined) when ``A`` is not positive definite.
    """
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1):
            L[i, j] = A[i, j]
    if not cholesky_lower_in_place(L):
        return False
    cholesky_inverse_into(L, out)
    return True


@_jit
def kinematics_terms(pin_out: tuple, dq: np.ndarray, eps: float, arm: np.ndarray) -> bool:
    """The law's arm terms from Pinocchio's outputs, written into the arm's record.

    pin_out : Pinocchio's arrays as it returns them (read, not kept): ``(M_upper, Minv_upper, J, p, R, nle, g,
    drift)``, the inertia (n, n) and its inverse with their upper triangles valid (older Pinocchio fills only
    those), the pad Jacobian (6, n) world-aligned, the pad pose p (3,) [m], R (3, 3), nle, g (n,) [Nm],
    drift (6,) = dJ dq. dq : (n,) [rad/s]; eps : regularisation of the task inertia's inverse.
    arm : a record of :func:`~.records.arm_dtype`: M, M_inv symmetric, J, p, R, nle, g, drift copied,
    Lam (6, 6) = (J M^-1 J^T + eps I)^-1, twist (6,) = J dq (A, L its scratch).
    Returns False when Lam could not be formed (not positive definite).
    """
    M_upper, Minv_upper, J_pin, p_pin, R_pin, nle_pin, g_pin, drift_pin = pin_out
    a = arm[0]
    M, M_inv, J, Lam, twist = a.M, a.M_inv, a.J, a.Lam, a.twist
    p, R, nle, g, drift, A = a.p, a.R, a.nle, a.g, a.drift, a.A
    n = M.shape[0]
    for i in range(3):
        p[i] = p_pin[i]
        for j in range(3):
            R[i, j] = R_pin[i, j]
    for i in range(n):
        nle[i] = nle_pin[i]
        g[i] = g_pin[i]
    for r in range(6):
        drift[r] = drift_pin[r]
        for j in range(n):
            J[r, j] = J_pin[r, j]
    for i in range(n):
        for j in range(i, n):
            M[i, j] = M_upper[i, j]
            M[j, i] = M_upper[i, j]
            M_inv[i, j] = Minv_upper[i, j]
            M_inv[j, i] = Minv_upper[i, j]
    for r in range(6):
        s = 0.0
        for j in range(n):
            s += J[r, j] * dq[j]
        twist[r] = s
    # A = J M^-1 J^T + eps I, its upper triangle summed entry by entry (about 7,000 flops: no scratch needed)
    for r in range(6):
        for c in range(r, 6):
            s = 0.0
            for i in range(n):
                ji = 0.0
                for j in range(n):
                    ji += M_inv[i, j] * J[c, j]
                s += J[r, i] * ji
            A[r, c] = s
            A[c, r] = s
        A[r, r] += eps
    return spd_inverse_into(A, Lam, a.L)


@_jit
def log3_into(R: np.ndarray, out: np.ndarray) -> None:
    """The rotation vector (3,) [rad] of the rotation matrix ``R`` (3, 3): ``exp3(out) = R``, angle in [0, pi].

    Matches ``pinocchio.log3`` to rounding: the axis-angle formula away from 0 and pi, its Taylor series
    near 0, and the axis from the diagonal near pi (where ``R - R^T`` vanishes).
    """
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    c = min(1.0, max(-1.0, 0.5 * (tr - 1.0)))
    theta = math.acos(c)
    wx = R[2, 1] - R[1, 2]
    wy = R[0, 2] - R[2, 0]
    wz = R[1, 0] - R[0, 1]
    if theta < 1e-4:
        f = 0.5 * (1.0 + theta * theta / 6.0)  # theta / (2 sin theta)
    elif theta < math.pi - 1e-3:
        f = 0.5 * theta / math.sin(theta)
    else:
        # near pi, where R - R^T vanishes: (R + R^T) / 2 = c I + (1 - c) a a^T gives the axis a from the
        # largest diagonal entry and its row; the sign (free at pi itself) from sin(theta) a = (R - R^T)^vee / 2
        d = 1.0 - c
        k = 0
        if R[1, 1] > R[k, k]:
            k = 1
        if R[2, 2] > R[k, k]:
            k = 2
        ak = math.sqrt(max(0.0, (R[k, k] - c) / d))
        for j in range(3):
            out[j] = ak if j == k else 0.5 * (R[k, j] + R[j, k]) / (d * ak)
        if out[0] * wx + out[1] * wy + out[2] * wz < 0.0:
            theta = -theta
        norm = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
        for j in range(3):
            out[j] *= theta / norm
        return
    out[0] = f * wx
    out[1] = f * wy
    out[2] = f * wz


@_jit
def _clip_norm3(v: np.ndarray, o: int, limit: float) -> None:
    n = math.sqrt(v[o] * v[o] + v[o + 1] * v[o + 1] + v[o + 2] * v[o + 2])
    if n > limit:
        f = limit / n
        v[o] *= f
        v[o + 1] *= f
        v[o + 2] *= f


@_jit
def _remove_along(v: np.ndarray, n: np.ndarray) -> None:
    s = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
    for i in range(3):
        v[i] -= s * n[i]


@_jit
def impedance_into(arm: np.ndarray, ref: np.ndarray, modes: np.ndarray, shaping: np.ndarray, state: tuple,
                   kn: float, add_gravity: bool, out: np.ndarray) -> None:
    """The impedance law of :mod:`.impedance` (its module docstring has the equations), written in place.

    Records (:mod:`.records`): arm (:func:`~.records.arm_dtype`, the arm's terms at the state), ref
    (:data:`~.records.REFERENCE_DTYPE`), modes (:data:`~.records.MODES_DTYPE`: B (6, 6), k, d (6,)), shaping
    (:func:`~.records.law_dtype`: ``use_axis`` / ``use_extra`` / ``use_posture`` say whether ``force_axis`` /
    ``extra_force_n`` / ``posture_nm``, joint torques (n,) [Nm] added to the posture before its projection,
    apply). state : ``(q, dq, q_rest)`` (n,) each [rad, rad/s, rad]; kn : the posture stiffness [Nm/rad];
    add_gravity : add g (the robot does not). out (:func:`~.records.terms_dtype`): tau (n,) [Nm], F (6,) task
    wrench, e (6,) pose error, de (6,) twist error, tau_null (n,); its work (7, max(n, 6)) is scratch.
    """
    q, dq, q_rest = state
    a_ = arm[0]
    M, M_inv, J, Lam, twist, drift, nle, g, p, R = (a_.M, a_.M_inv, a_.J, a_.Lam, a_.twist, a_.drift, a_.nle, a_.g,
                                                     a_.p, a_.R)
    r_ = ref[0]
    p_ref, R_ref, twist_ref, accel_ref = r_.p, r_.R, r_.twist, r_.accel
    m_ = modes[0]
    B, k, d = m_.B, m_.k, m_.d
    sh = shaping[0]
    force_axis, use_axis, press_n = sh.force_axis, sh.use_axis, sh.press_n
    extra_force_n, use_extra, posture_nm, use_posture = sh.extra_force_n, sh.use_extra, sh.posture_nm, sh.use_posture
    o_ = out[0]
    tau, F, e, de, tau_null, work = o_.tau, o_.F, o_.e, o_.de, o_.tau_null, o_.work
    n = M.shape[0]
    a = work[0]
    mod = work[1]
    t1 = work[2]
    # pose error [p_ref - p ; log(R_ref R^T)], clipped
    for i in range(3):
        e[i] = p_ref[i] - p[i]
    Rrel = work[4:7, :3]  # R_ref R^T
    for i in range(3):
        for j in range(3):
            s = 0.0
            for m in range(3):
                s += R_ref[i, m] * R[j, m]
            Rrel[i, j] = s
    log3_into(Rrel, e[3:])
    _clip_norm3(e, 0, sh.max_position_error_m)
    _clip_norm3(e, 3, sh.max_rotation_error_rad)
    for i in range(6):
        de[i] = twist_ref[i] - twist[i]
        a[i] = accel_ref[i] - drift[i]
    if use_axis:
        _remove_along(e, force_axis)
        _remove_along(de, force_axis)
        _remove_along(a, force_axis)
    # F = B (k * (B^T e) + d * (B^T de)) + Lam a
    for i in range(6):
        se = 0.0
        sd = 0.0
        for j in range(6):
            se += B[j, i] * e[j]
            sd += B[j, i] * de[j]
        mod[i] = k[i] * se + d[i] * sd
    for i in range(6):
        s = 0.0
        for j in range(6):
            s += B[i, j] * mod[j]
        la = 0.0
        for j in range(6):
            la += Lam[i, j] * a[j]
        F[i] = s + la
    if use_axis:
        lam_n = 0.0
        vn = 0.0
        for i in range(3):
            vn += twist[i] * force_axis[i]
            for j in range(3):
                lam_n += force_axis[i] * Lam[i, j] * force_axis[j]
        f = press_n + lam_n * sh.normal_damping_1_s * vn
        for i in range(3):
            F[i] -= f * force_axis[i]
    if use_extra:
        for i in range(3):
            F[i] += extra_force_n[i]
    # posture tau0 = M (kn (q_rest - q) - 2 sqrt(kn) dq) [+ posture_nm]; N^T tau0 = tau0 - J^T Lam J M^-1 tau0
    c = 2.0 * math.sqrt(kn)
    for i in range(n):
        t1[i] = kn * (q_rest[i] - q[i]) - c * dq[i]
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M[i, j] * t1[j]
        tau_null[i] = s + posture_nm[i] if use_posture else s  # tau0, for now
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M_inv[i, j] * tau_null[j]
        t1[i] = s  # M^-1 tau0
    for r in range(6):
        s = 0.0
        for j in range(n):
            s += J[r, j] * t1[j]
        mod[r] = s  # J M^-1 tau0
    for r in range(6):
        s = 0.0
        for j in range(6):
            s += Lam[r, j] * mod[j]
        a[r] = s  # Lam J M^-1 tau0
    for i in range(n):
        s = 0.0
        sf = 0.0
        for r in range(6):
            s += J[r, i] * a[r]
            sf += J[r, i] * F[r]
        tau_null[i] -= s
        tau[i] = sf + tau_null[i] + nle[i]
        if not add_gravity:
            tau[i] -= g[i]


@_jit
def disturbance_into(arm: tuple, dq: np.ndarray, tau_applied: np.ndarray, wrench: np.ndarray, dt_s: float,
                     gain: float, watch: np.ndarray) -> float:
    """One cycle of :class:`~.watch.DisturbanceWatch`: ``tau_d += gain (raw - tau_d)`` with
    ``raw = M (dq - dq_prev) / dt + nle - tau_applied - J^T wrench`` (all (n,) [Nm]).

    arm : ``(M, nle, J)``, (n, n), (n,) [Nm], (6, n) world-aligned; dq (n,) [rad/s]; wrench (6,) [N, Nm];
    watch : the watch's record (:func:`~.records.disturbance_dtype`: tau_d, limit, dq_prev, which becomes
    ``dq``, raw scratch). Returns ``max |tau_d| / limit``."""
    M, nle, J = arm
    w_ = watch[0]
    tau_d, limit, dq_prev, raw = w_.tau_d, w_.limit, w_.dq_prev, w_.raw
    n = dq.shape[0]
    for i in range(n):
        raw[i] = (dq[i] - dq_prev[i]) / dt_s
    ratio = 0.0
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M[i, j] * raw[j]
        w = 0.0
        for r in range(6):
            w += J[r, i] * wrench[r]
        x = s + nle[i] - tau_applied[i] - w
        tau_d[i] += (x - tau_d[i]) * gain
        ratio = max(ratio, abs(tau_d[i]) / limit[i])
    for i in range(n):
        dq_prev[i] = dq[i]
    return ratio


@_jit
def task_modes_into(Lam: np.ndarray, K: np.ndarray, zeta: float, max_omega_rad_s: float, modes: np.ndarray) -> None:
    """The modes of :func:`~.impedance.task_modes` into the record ``modes`` (:data:`~.records.MODES_DTYPE`: B
    (6, 6), k, d (6,)): eigen-decomposition of ``S^-1 Lam S^-1`` (S = diag(sqrt(K))), modal stiffness capped at
    ``max_omega^2 m``, damping ``2 zeta sqrt(k m)``."""
    m_ = modes[0]
    B, k, d = m_.B, m_.k, m_.d
    s = np.sqrt(K)
    m, U = np.linalg.eigh(Lam / np.outer(s, s))
    for i in range(6):
        mi = max(m[i], 1e-12)
        ki = min(1.0, max_omega_rad_s * max_omega_rad_s * mi)
        k[i] = ki
        d[i] = 2.0 * zeta * math.sqrt(ki * mi)
        for r in range(6):
            B[r, i] = s[r] * U[r, i]


@_jit
def reference_into(board: np.ndarray, setpoint: tuple, normal: tuple, scale: float, ref: np.ndarray) -> None:
    """The world reference of a board-frame setpoint at the time scale ``scale``.

    board : a record of :data:`~.records.BOARD_DTYPE` (origin (3,) [m], R (3, 3), its third axis the outward
    normal); setpoint : ``(xy, v_xy, a_xy, R, omega, domega)``, the in-plane position [m], velocity,
    acceleration (2,), the orientation (3, 3) and its rates (3,); normal : ``(h, v_h, a_h)`` along the normal.
    ref : the reference's record (:data:`~.records.REFERENCE_DTYPE`), written: p (3,), R (3, 3), twist and
    accel (6,), velocities times ``scale`` and accelerations times ``scale^2``.
    """
    xy, v_xy, a_xy, R_sp, omega, domega = setpoint
    h, v_h, a_h = normal
    b_ = board[0]
    origin, R_board = b_.origin, b_.R
    r_ = ref[0]
    p_ref, R_ref, twist_ref, accel_ref = r_.p, r_.R, r_.twist, r_.accel
    s2 = scale * scale
    for i in range(3):
        p_ref[i] = origin[i] + R_board[i, 0] * xy[0] + R_board[i, 1] * xy[1] + R_board[i, 2] * h
        twist_ref[i] = (R_board[i, 0] * v_xy[0] + R_board[i, 1] * v_xy[1] + R_board[i, 2] * v_h) * scale
        twist_ref[3 + i] = omega[i] * scale
        accel_ref[i] = (R_board[i, 0] * a_xy[0] + R_board[i, 1] * a_xy[1] + R_board[i, 2] * a_h) * s2
        accel_ref[3 + i] = domega[i] * s2
        for j in range(3):
            R_ref[i, j] = R_sp[i, j]


@_jit
def tool_in_board(board: np.ndarray, arm: np.ndarray, wrench: np.ndarray, xyh: np.ndarray,
                  v_board: np.ndarray) -> float:
    """The pad in the board frame: board, a record of :data:`~.records.BOARD_DTYPE` (origin (3,) [m], R (3, 3)
    its axes, the third the outward normal); arm, the arm's record (:func:`~.records.arm_dtype`: the pad at p
    (3,) [m] moving with twist (6,)). Out: ``xyh`` (3,) = R^T (p - origin), ``v_board`` (3,) = R^T v. Returns
    the normal force [N], ``wrench[:3] . normal`` (positive when the board pushes the pad back)."""
    b_ = board[0]
    origin, R_board = b_.origin, b_.R
    a_ = arm[0]
    p, twist = a_.p, a_.twist
    f = 0.0
    for j in range(3):
        x = 0.0
        v = 0.0
        for i in range(3):
            x += (p[i] - origin[i]) * R_board[i, j]
            v += R_board[i, j] * twist[i]
        xyh[j] = x
        v_board[j] = v
        f += wrench[j] * R_board[j, 2]
    return f


@_jit
def trace_row(r: np.ndarray, clock: tuple, setpoint: tuple, xyh: np.ndarray, p_ref: np.ndarray, p: np.ndarray,
              forces: tuple) -> None:
    """One row ``r`` of the controller's trace (its columns: ``controller.core.TRACE_COLUMNS``).

    clock : ``(t_s, phase, scale)``, the controller's time [s], the phase's code, the time scale; setpoint :
    ``(has_setpoint, xy, v_xy, a_xy, contact)``, in-plane rates written as executed (velocity x scale,
    acceleration x scale^2), without a setpoint columns 2-10 and 19 stay; xyh (3,) the pad in the board frame
    [m]; p_ref, p (3,) the reference and the pad [m]; forces : ``(force_n, press_n)`` measured, commanded [N]."""
    t_s, phase, scale = clock
    has_setpoint, xy, v_xy, a_xy, contact = setpoint
    force_n, press_n = forces
    r[0] = t_s
    r[1] = phase
    if has_setpoint:
        s2 = scale * scale
        for i in range(2):
            r[2 + i] = xy[i]
            r[4 + i] = v_xy[i] * scale
            r[6 + i] = a_xy[i] * s2
        for i in range(3):
            r[8 + i] = xyh[i]
        r[19] = contact
    for i in range(3):
        r[11 + i] = p_ref[i]
        r[14 + i] = p[i]
    r[17] = force_n
    r[18] = press_n
    r[20] = scale
