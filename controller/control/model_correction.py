"""A bounded disturbance observer for the arm's own static torques: what the nominal model misses, integrated.

The controller's model is the description; a real arm's links weigh what
they weigh and its tool what the user mounted. The torque the model misses,
``delta`` (n,) [Nm], shows in the disturbance watch's residual
(:class:`~.watch.DisturbanceWatch`)::

    tau_d = M (dq_k - dq_{k-1}) / dt + nle + c - tau_applied - J^T w

when the correction ``c`` is counted as part of the model (``nle + c``,
``g + c``; where the robot adds gravity itself it adds its own, not ``c``). Since the robot applied ``c``
too, ``tau_d = c - delta`` whatever ``c`` is: the observer

    c = Y(q) theta + z,     dz/dt = -tau_d / T_i,   |z_i| <= z_max_i

drives ``c`` to ``delta`` with the time constant ``T_i`` (a first-order
estimator; it does not feed back on the pad's position). ``Y(q) theta`` is the estimated
flange load (:mod:`controller.tool_estimate`) once it is fitted: its gravity
torque follows the pose exactly, ``z`` keeps what the load does not explain
(link masses, centres of mass), at the pose where it was learned.

Why it stays bounded in contact: ``J^T w`` takes the measured contact wrench
out, friction included (the pad's force-torque reading), so the friction of
a wipe is not a disturbance; ``z`` is clipped per joint (anti-windup: the
clip is the integrator's state, it never winds beyond it), and when a joint
stays at its clip the arm does not match its model beyond what the
controller absorbs: a named warning (:data:`MODEL_MISMATCH`), not a fault.
Not integrated: a cycle whose applied torque is unknown (a hold, a skipped
state: the residual is not evaluated). Nothing resets at a phase change: the
arm's weight does not change with the phase; a restart keeps it too.

In the same residual: inertia errors ``(M - M_true) ddq``, zero-mean over a
wiping period, and the change of the links' static error across the wiped
area; ``c`` follows them below ``1 / (2 pi T_i)`` (3.2 Hz at 0.05 s: a
disturbance observer on the measured acceleration, docs/controller.md says
what that bought on the heavier plants); unmodelled joint friction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numba as nb
import numpy as np

from controller.tool_estimate import GRAVITY_M_S2, TORQUE_NOISE_NM, tool_regressor_into
from interfaces.errors import ConfigError
from runtime.config import In, check_declared

#: The status warning's name when the correction stays at its bound.
MODEL_MISMATCH = "model_mismatch"

_jit = nb.njit(cache=True)


@dataclass(frozen=True)
class CorrectionParams:
    """The observer's settings (``[controller.model]``).

    enabled : add the correction (off, the default: the nominal model only; the estimate is still made and
    reported). Opt-in: on, a random reachable board (``lamps up --no-network --board random:4 --seed 4 --stains
    5``) ended in the robot side's FAULT-hold (42.6 N) where the nominal model cleans it at 13.2 N, and the roll
    turns A7 at up to 1.6 rad/s at every start; both are to be understood before it is the default.
    integral_s : T_i, the time constant the correction follows the missing torque with [s].
    bound_share : ``z_max`` per joint as a share of the joint's torque limit.
    warn_s : a joint at its bound this long raises :data:`MODEL_MISMATCH` [s].
    identify_s : the identification motion's length before the skill starts [s] (0: none;
    :mod:`controller.arm_model`); identify_roll_rad : how far it rolls the pad about its normal [rad].
    torque_noise_nm : the joint-torque sensors' noise (standard deviation) [Nm]: the flange load estimate fits a
    direction when its standard error at this noise is within 5 g m (:mod:`controller.tool_estimate`).
    """

    enabled: bool = False
    integral_s: Annotated[float, In(0.01, 10.0)] = 0.05
    bound_share: Annotated[float, In(0.0, 0.5)] = 0.15
    warn_s: Annotated[float, In(0.0, 60.0)] = 0.5
    identify_s: Annotated[float, In(0.0, 30.0)] = 0.0
    identify_roll_rad: Annotated[float, In(0.0, 1.5)] = 0.5
    torque_noise_nm: Annotated[float, In(0.001, 5.0)] = TORQUE_NOISE_NM

    def __post_init__(self) -> None:
        check_declared(self, "controller.model")
        if not isinstance(self.enabled, bool):
            raise ConfigError(f"[controller.model] enabled must be true or false, got {self.enabled!r}")


@_jit
def correction_into(Y: np.ndarray, theta: np.ndarray, z: np.ndarray, out: np.ndarray) -> None:
    """``out`` (n,) = ``Y theta + z`` (Y (n, 4), theta (4,), z (n,))."""
    for i in range(out.shape[0]):
        s = z[i]
        for k in range(4):
            s += Y[i, k] * theta[k]
        out[i] = s


@_jit
def integrate_into(z: np.ndarray, tau_d: np.ndarray, gain: float, z_max: np.ndarray) -> bool:
    """``z -= gain tau_d``, clipped to ``+-z_max``; True when a joint is at its clip."""
    at = False
    for i in range(z.shape[0]):
        v = z[i] - gain * tau_d[i]
        if v >= z_max[i]:
            v, at = z_max[i], True
        elif v <= -z_max[i]:
            v, at = -z_max[i], True
        z[i] = v
    return at


class ModelCorrection:
    """The observer of the module docstring; no allocation per tick.

    tau_max_nm : (n,) the joints' torque limits [Nm] (the clip is ``bound_share`` of them).
    """

    def __init__(self, params: CorrectionParams, tau_max_nm: np.ndarray) -> None:
        self.p = params
        n = len(tau_max_nm)
        self.z_max = params.bound_share * np.asarray(tau_max_nm, float)
        self.z = np.zeros(n)
        self.theta = np.zeros(4)  # the flange load in use: (m, m c) in the pad frame
        self.Y = np.zeros((n, 4))
        self.c = np.zeros(n)  # this tick's correction [Nm]
        self.missing = np.zeros(n)  # this tick's estimate of the missing torque c - tau_d [Nm]
        self.at_bound_s = 0.0
        self.warning = ""

    def apply(self, kin) -> np.ndarray:
        """Count the correction as part of the model of ``kin`` (its :class:`~.impedance.Kinematics`, updated
        this tick): ``nle += c``, ``g += c``. Returns ``c`` (n,) [Nm]. When the robot compensates gravity the law
        adds no ``g``: the caller adds ``c`` to its command itself, and the robot's own gravity, which the watch
        adds to the applied torque, is ``g - c``."""
        tool_regressor_into(kin.J, kin.R, GRAVITY_M_S2, self.Y)
        if not self.p.enabled:
            self.c[:] = 0.0
            return self.c
        correction_into(self.Y, self.theta, self.z, self.c)
        kin.nle += self.c  # the law's C dq is nle - g: unchanged
        kin.g += self.c
        return self.c

    def update(self, tau_d: np.ndarray, dt_s: float) -> None:
        """One evaluated cycle of length ``dt_s`` [s] with the watch's residual ``tau_d`` (n,) [Nm]."""
        np.subtract(self.c, tau_d, out=self.missing)
        if not self.p.enabled or dt_s <= 0.0:
            return
        at = integrate_into(self.z, tau_d, min(dt_s / self.p.integral_s, 1.0), self.z_max)
        self.at_bound_s = self.at_bound_s + dt_s if at else 0.0
        if self.at_bound_s >= self.p.warn_s and not self.warning:
            j = int(np.argmax(np.abs(self.z) / np.maximum(self.z_max, 1e-9)))
            self.warning = (f"{MODEL_MISMATCH}: the arm's static torque differs from its model by more than the "
                            f"correction absorbs (A{j + 1} at {self.z[j]:+.1f} Nm, bound {self.z_max[j]:.1f} Nm for "
                            f"{self.p.warn_s:g} s): check the tool's load data and the arm's description")

    def use_load(self, theta: np.ndarray) -> None:
        """Take the fitted flange load ``theta`` (4,) into the correction, keeping ``c`` continuous at this pose:
        ``z -= Y (theta - theta_old)``."""
        if not self.p.enabled:
            return
        d = theta - self.theta
        self.z -= self.Y @ d
        np.clip(self.z, -self.z_max, self.z_max, out=self.z)
        self.theta[:] = theta
