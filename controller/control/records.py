"""The compiled law's named arguments: numpy structured records of fixed-shape arrays and numbers.

A kernel of :mod:`.kernels` takes a few of these instead of dozens of positional arrays: one record per
purpose (the arm's terms at this state, the reference, the task's modes, the law's shaping and gains, the
law's outputs), each a one-element structured array whose fields are the arrays the kernel reads by name
(``arm.M``, ``ref.twist``). The objects the Python side uses (:class:`~.impedance.Kinematics`,
:class:`~.impedance.Reference`, ...) hold views of their record's fields, so a kernel writes what they
read without a copy; a record reaches numba as one array (the dispatcher's fast path, faster than a named
tuple, which numba types field by field on every call).

Shapes: ``n`` joints (the arm's ``nq``); 6-vectors are twists and wrenches (linear first, world axes).
"""

from __future__ import annotations

import numpy as np


def arm_dtype(n: int) -> np.dtype:
    """The arm's terms at (q, dq) (:class:`~.impedance.Kinematics`): M, M_inv (n, n) [kg m^2]; J (6, n);
    Lam (6, 6) task inertia; twist (6,) = J dq; drift (6,) = dJ dq; nle, g (n,) [Nm]; p (3,) [m];
    R (3, 3); A, L (6, 6) scratch of the task inertia's Cholesky."""
    return np.dtype([("M", "f8", (n, n)), ("M_inv", "f8", (n, n)), ("J", "f8", (6, n)), ("Lam", "f8", (6, 6)),
                     ("twist", "f8", 6), ("drift", "f8", 6), ("nle", "f8", n), ("g", "f8", n), ("p", "f8", 3),
                     ("R", "f8", (3, 3)), ("A", "f8", (6, 6)), ("L", "f8", (6, 6))], align=True)


#: The reference (:class:`~.impedance.Reference`): p (3,) [m], R (3, 3), twist (6,), accel (6,), world axes.
REFERENCE_DTYPE = np.dtype([("p", "f8", 3), ("R", "f8", (3, 3)), ("twist", "f8", 6), ("accel", "f8", 6)],
                           align=True)

#: The task's modes (:class:`~.impedance.TaskModes`): B (6, 6) mode shapes, k, d (6,) modal stiffness, damping.
MODES_DTYPE = np.dtype([("B", "f8", (6, 6)), ("k", "f8", 6), ("d", "f8", 6)], align=True)

#: A board frame: origin (3,) [m] (world), R (3, 3) its axes as columns, the third the outward normal.
BOARD_DTYPE = np.dtype([("origin", "f8", 3), ("R", "f8", (3, 3))], align=True)


def law_dtype(n: int) -> np.dtype:
    """The impedance law's shaping and gains for one evaluation (:class:`~.impedance.TaskShaping` and
    :class:`~.params.ImpedanceParams`, flattened): force_axis (3,) unit, world, used when ``use_axis``;
    press_n [N]; normal_damping_1_s [1/s]; max_position_error_m [m], max_rotation_error_rad [rad];
    extra_force_n (3,) [N] when ``use_extra``; posture_nm (n,) [Nm] when ``use_posture``;
    nullspace_stiffness_nm_rad [Nm/rad]; add_gravity: the law adds g (the robot does not)."""
    return np.dtype([("force_axis", "f8", 3), ("extra_force_n", "f8", 3), ("posture_nm", "f8", n),
                     ("press_n", "f8"), ("normal_damping_1_s", "f8"), ("max_position_error_m", "f8"),
                     ("max_rotation_error_rad", "f8"), ("nullspace_stiffness_nm_rad", "f8"),
                     ("use_axis", "?"), ("use_extra", "?"), ("use_posture", "?"), ("add_gravity", "?")],
                    align=True)


def terms_dtype(n: int) -> np.dtype:
    """The law's outputs (:class:`~.impedance.ImpedanceTerms`): tau (n,) [Nm], F (6,) task wrench, e (6,) pose
    error, de (6,) twist error, tau_null (n,) [Nm]; work (7, max(n, 6)) the kernel's scratch."""
    return np.dtype([("tau", "f8", n), ("F", "f8", 6), ("e", "f8", 6), ("de", "f8", 6), ("tau_null", "f8", n),
                     ("work", "f8", (7, max(n, 6)))], align=True)


def disturbance_dtype(n: int) -> np.dtype:
    """The disturbance watch's state (:class:`~.watch.DisturbanceWatch`): tau_d (n,) filtered unexplained
    torque [Nm], limit (n,) [Nm], dq_prev (n,) the last cycle's velocity [rad/s], raw (n,) scratch."""
    return np.dtype([("tau_d", "f8", n), ("limit", "f8", n), ("dq_prev", "f8", n), ("raw", "f8", n)], align=True)


def new_record(dtype: np.dtype) -> np.ndarray:
    """A zeroed one-element record array of ``dtype``: what a kernel takes; ``view(rec, name)`` views a field."""
    return np.zeros(1, dtype)


def view(rec: np.ndarray, name: str) -> np.ndarray:
    """The field ``name`` of the one-element record ``rec``: a view (writes reach the kernel's record)."""
    return rec[name][0]


class RecordViews:
    """A base for objects whose array attributes view one record (``rec``): assigning to such an attribute
    (``ref.p_m = x``) copies ``x`` into the record, so the kernels see it; other attributes behave as usual.

    ``_views`` maps each such attribute to its field; :meth:`_bind` makes the record and the views.
    """

    _views: dict[str, str] = {}
    rec: np.ndarray  #: the one-element record the views look into (made by :meth:`_bind`)

    def _bind(self, dtype: np.dtype) -> None:
        rec = new_record(dtype)
        object.__setattr__(self, "rec", rec)
        for attr, name in self._views.items():
            object.__setattr__(self, attr, view(rec, name))

    def __setattr__(self, name: str, value: object) -> None:
        if name in self._views and name in self.__dict__:
            self.__dict__[name][...] = value
        else:
            object.__setattr__(self, name, value)
