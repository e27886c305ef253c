"""The load on the flange the description does not carry: its mass and centre of mass, from joint torques.

A point mass ``m`` at ``c`` (pad frame, from the pad centre) on the arm takes
the joint torque ``tau = Y(q) theta`` to hold, linear in
``theta = (m, m c_x, m c_y, m c_z)``::

    Y = [ -J_v^T g | J_w^T [g]_x R ]        (n, 4)

with ``J_v``, ``J_w`` (3, n) the pad Jacobian's linear and angular rows
(world-aligned), ``R`` (3, 3) the pad's orientation, ``g`` = (0, 0, -9.81)
m/s^2 and ``[g]_x`` its cross-product matrix (the holding torque of the
force ``m g`` at the point ``p + R c``: ``-J_v(p + R c)^T m g`` with
``J_v(p + R c) = J_v - [R c]_x J_w``). ``tests/test_tool_estimate.py`` checks
it against Pinocchio's gravity of a model with the mass added.

:class:`ToolEstimate` collects samples ``(Y(q), tau_missing)`` while the arm
moves freely (the torque the model misses, what the
:class:`~controller.control.model_correction.ModelCorrection` observer
measures) and solves the least-squares fit over them: the normal equations
are accumulated (4 x 4 and 4 numbers), so memory does not grow with samples.
One pose fixes the mass and the centre of mass across gravity; the part along
gravity needs a second orientation of the flange (the approach turns it, the
identification roll does on purpose).

What the samples do not tell is not made up: the fit is solved in the
eigenvectors of the normal equations ``A = sum Y^T Y`` whose standard error
``sigma / sqrt(lambda)`` is within :data:`MAX_COM_ERROR_KG_M` of ``m c``;
along the others ``theta`` keeps its prior, the load's centre of mass at the
pad centre. ``sigma`` is the joint-torque sensor's noise, a setting
(``[controller.model] torque_noise_nm``), not the fit's residual: where the
links weigh other than their model the residual is their model error (1.3
Nm RMS on the +30 % links plant with the controller adding gravity), and a
residual-based threshold dropped the directions a load on the flange needs
to take the part of that error it can explain. What is judged is the
excitation: a wall board's approach keeps the pad's y axis along gravity
all the way, its eigenvalue stays near zero (25 N^2 m^2 / kg^2 over 1215
samples, a standard error of 20 g m at 0.1 Nm), and without the roll a
least-squares fit put a 1.4 kg tool 10-55 cm off the flange along it.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from arm.description import ERASER_LINK

#: Gravity in the world (robot base) frame [m/s^2].
GRAVITY_M_S2 = np.array([0.0, 0.0, -9.81])
#: No fit while the mass's own column of the normal equations, per sample, is under this [N^2 m^2 / kg^2]: an arm
#: that never moved.
MIN_EXCITATION = 1e-4
#: A fit needs at least this many samples.
MIN_SAMPLES = 20
#: A direction of ``theta`` is taken from the samples when its standard error, at the sensor's noise, is within this
#: [kg m] (5 mm for a 1 kg load).
MAX_COM_ERROR_KG_M = 0.005
#: The joint-torque noise a standard error is judged at when none is given [Nm] (``[controller.model]
#: torque_noise_nm``'s default, argued in docs/controller.md).
TORQUE_NOISE_NM = 0.1

_jit = nb.njit(cache=True)


@_jit
def tool_regressor_into(J: np.ndarray, R: np.ndarray, g: np.ndarray, Y: np.ndarray) -> None:
    """``Y`` (n, 4) = ``[-J_v^T g | J_w^T [g]_x R]`` for the pad Jacobian ``J`` (6, n), pad orientation ``R``
    (3, 3), gravity ``g`` (3,) [m/s^2] (see the module docstring)."""
    # [g]_x R, column by column: g x R[:, k]
    gx0, gx1, gx2 = g[0], g[1], g[2]
    for i in range(J.shape[1]):
        Y[i, 0] = -(J[0, i] * gx0 + J[1, i] * gx1 + J[2, i] * gx2)
        for k in range(3):
            c0 = gx1 * R[2, k] - gx2 * R[1, k]
            c1 = gx2 * R[0, k] - gx0 * R[2, k]
            c2 = gx0 * R[1, k] - gx1 * R[0, k]
            Y[i, 1 + k] = J[3, i] * c0 + J[4, i] * c1 + J[5, i] * c2


@_jit
def accumulate_into(Y: np.ndarray, tau: np.ndarray, A: np.ndarray, b: np.ndarray) -> float:
    """``A += Y^T Y``, ``b += Y^T tau`` (A (4, 4), b (4,), Y (n, 4), tau (n,)); returns ``tau . tau``."""
    n = Y.shape[0]
    tt = 0.0
    for i in range(n):
        tt += tau[i] * tau[i]
        for r in range(4):
            b[r] += Y[i, r] * tau[i]
            for c in range(4):
                A[r, c] += Y[i, r] * Y[i, c]
    return tt


class ToolEstimate:
    """Least-squares mass and centre of mass of an unlisted flange load from samples ``(Y, tau)``.

    Parameters
    ----------
    pad_in_flange_m : (3,) the pad centre in the flange frame [m] (the flange's axes are the pad's).
    torque_noise_nm : the joint-torque sensor's noise (standard deviation) [Nm], > 0: what a direction's standard
    error is judged at (module docstring).
    """

    def __init__(self, pad_in_flange_m: np.ndarray, torque_noise_nm: float = TORQUE_NOISE_NM) -> None:
        if not np.isfinite(torque_noise_nm) or torque_noise_nm <= 0.0:
            raise ValueError(f"ToolEstimate: torque_noise_nm must be a positive number [Nm], got {torque_noise_nm!r}")
        self.torque_noise_nm = float(torque_noise_nm)
        self.pad_in_flange_m = np.asarray(pad_in_flange_m, float).copy()
        self.A = np.zeros((4, 4))
        self.b = np.zeros(4)
        self.tt = 0.0
        self.n = 0
        self.Y = np.zeros((7, 4))
        self.mass_kg = 0.0
        self.com_flange_m = np.zeros(3)
        self.residual_rms_nm = 0.0  # the fit's residual torque, RMS over samples and joints [Nm]
        self.theta = np.zeros(4)  # (m, m c) in the pad frame
        self.unobserved = 0  # directions of theta the samples did not tell (kept at the prior)
        self.valid = False

    @classmethod
    def for_model(cls, model, torque_noise_nm: float = TORQUE_NOISE_NM) -> ToolEstimate:
        """For a :class:`~arm.robot_model.RobotModel` (the pad frame's place on the flange from its model)."""
        m = model.model
        flange = m.frames[m.getFrameId(ERASER_LINK)].placement
        pad = m.frames[model.tcp_id].placement
        return cls((flange.inverse() * pad).translation, torque_noise_nm)

    def reset(self) -> None:
        self.A[:] = 0.0
        self.b[:] = 0.0
        self.tt = 0.0
        self.n = 0
        self.valid = False

    def add(self, J: np.ndarray, R: np.ndarray, tau_missing: np.ndarray) -> None:
        """One sample: pad Jacobian ``J`` (6, n), orientation ``R`` (3, 3), the torque the model misses (n,) [Nm]."""
        tool_regressor_into(J, R, GRAVITY_M_S2, self.Y)
        self.tt += accumulate_into(self.Y, tau_missing, self.A, self.b)
        self.n += 1

    def _rms(self, theta: np.ndarray) -> float:
        """The residual torque's RMS over samples and joints [Nm] of ``theta`` (4,): from the normal equations,
        ``tau.tau - 2 theta.b + theta.A theta``."""
        ss = max(self.tt - 2.0 * float(theta @ self.b) + float(theta @ self.A @ theta), 0.0)
        return float(np.sqrt(ss / (self.n * self.Y.shape[0])))

    def solve(self) -> bool:
        """Fit the samples so far; True (and :attr:`mass_kg`, :attr:`com_flange_m`, :attr:`theta` set) when there
        are enough and the mass's column moved (:data:`MIN_EXCITATION`); what they do not tell keeps its prior
        (the module docstring, :attr:`unobserved`)."""
        if self.n < MIN_SAMPLES:
            return False
        lam, V = np.linalg.eigh(self.A)
        if lam[-1] <= 0.0 or self.A[0, 0] < MIN_EXCITATION * self.n:
            return False  # the mass's own column never moved: nothing to fit
        s = self.torque_noise_nm
        told = lam * MAX_COM_ERROR_KG_M ** 2 >= s * s  # s / sqrt(lambda) <= MAX_COM_ERROR_KG_M
        if not told.any():
            return False  # the samples tell nothing at the sensor's noise
        self.unobserved = int(4 - told.sum())
        # the prior (m c = 0: the pad centre) along what the samples did not tell
        Vt = V[:, told]
        theta = Vt @ ((Vt.T @ self.b) / lam[told])
        self.theta[:] = theta
        self.mass_kg = float(theta[0])
        com_pad = theta[1:] / theta[0] if abs(theta[0]) > 1e-3 else np.zeros(3)
        self.com_flange_m[:] = com_pad + self.pad_in_flange_m
        self.residual_rms_nm = self._rms(theta)
        self.valid = True
        return True
