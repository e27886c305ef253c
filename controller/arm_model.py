"""What the controller learns about the arm it drives: the flange load and the static torque its model misses.

:class:`ArmModel` owns the correction observer
(:class:`~controller.control.model_correction.ModelCorrection`) and the
flange load estimate (:class:`~controller.tool_estimate.ToolEstimate`), and
the identification motion that lets the estimate see the load's centre of
mass along gravity: before the skill starts, the pad rolls about its own
normal, ``a(t) = A sin(2 pi t / T)`` over one period ``T`` (out to +A, back,
out to -A, back: the joints' friction acts both ways about as long). The
approach alone keeps the pad facing the board, and a load's offset along
gravity then turns no joint at any of its poses.

Timeline: identification (``identify_s``, begun only while the controller
waits for its first board, so a board known at once skips it) -> approach (samples of slow free
motion) -> the first contact: the fit is handed to the correction (its
gravity torque then follows the pose).
"""

from __future__ import annotations

import math

import numpy as np

from interfaces.arm_estimate import ArmEstimate
from interfaces.messages import Phase

from .control.model_correction import ModelCorrection
from .tool_estimate import ToolEstimate, accumulate_into

#: Before the first contact, one tool-estimate sample every this many ticks while the arm moves freely, no joint
#: faster than :data:`TOOL_SAMPLE_MAX_SPEED_RAD_S` (the residual's joint friction grows with speed).
TOOL_SAMPLE_EVERY_TICKS = 5
TOOL_SAMPLE_MAX_SPEED_RAD_S = 1.0
_HALTED = (Phase.FAULT, Phase.ESTOP)


class ArmModel:
    """Correction, load estimate and identification motion of one controller (see the module docstring).

    params : :class:`~controller.control.model_correction.CorrectionParams`; model : the controller's
    :class:`~arm.robot_model.RobotModel`; contact_threshold_n : a wrench above it is a touch [N].
    """

    def __init__(self, params, model, contact_threshold_n: float) -> None:
        self.p = params
        self.correction = ModelCorrection(params, model.limits.tau_max)
        self.tool = ToolEstimate.for_model(model, params.torque_noise_nm)
        self.fitted = False  # the fit was made (at the first contact) and handed to the correction
        self.identify_t_s = 0.0  # time spent in the identification motion [s]
        self._every = 0
        self._touch2 = contact_threshold_n ** 2
        self._Rz = np.eye(3)
        j = model.joints  # the nominal joint friction, taken out of the samples (the correction keeps it)
        self._fv = np.asarray(j.viscous_nm_s_rad, float)
        self._fc = np.asarray(j.coulomb_nm, float)
        self._v_eps = float(j.coulomb_velocity_rad_s)
        self._sample = np.zeros(model.nq)
        self._tmp = np.zeros(model.nq)

    def compile(self, kin) -> None:
        """Compile the kernels for the arrays the tick passes (no state left behind)."""
        c = self.correction
        c.apply(kin)
        c.update(np.zeros(len(c.z)), 0.0)
        accumulate_into(self.tool.Y, c.c, np.zeros((4, 4)), np.zeros(4))
        self.tool.add(kin.J, kin.R, c.c)
        self.tool.reset()

    def after_watch(self, tau_d: np.ndarray, kin, dq: np.ndarray, wrench: np.ndarray, dt_s: float,
                    phase: str) -> None:
        """An evaluated cycle of the disturbance watch (its residual ``tau_d`` (n,) [Nm]): integrate, and before the
        first contact take a sample of slow free motion every :data:`TOOL_SAMPLE_EVERY_TICKS` ticks."""
        # DONE: the arm rests where the skill left it; the correction stands (a report then reads the same figures
        # from whichever status was the last)
        self.correction.update(tau_d, 0.0 if phase == Phase.DONE else dt_s)
        if self.fitted:
            return
        self._every += 1
        if self._every < TOOL_SAMPLE_EVERY_TICKS:
            return
        self._every = 0
        touching = wrench[0] ** 2 + wrench[1] ** 2 + wrench[2] ** 2 > self._touch2
        x = self._sample
        np.abs(dq, out=x)
        if touching or x.max() > TOOL_SAMPLE_MAX_SPEED_RAD_S or phase in _HALTED:
            return
        # the missing torque less the nominal friction tau_f = Fv dq + Fc tanh(dq / v_eps)
        np.divide(dq, self._v_eps, out=x)
        np.tanh(x, out=x)
        x *= self._fc
        np.multiply(self._fv, dq, out=self._tmp)
        x += self._tmp
        np.subtract(self.correction.missing, x, out=x)
        self.tool.add(kin.J, kin.R, x)

    def first_contact(self) -> None:
        """Fit the load from the free motion's samples and hand it to the correction (once)."""
        if self.fitted:
            return
        self.fitted = True
        if self.tool.solve():
            self.correction.use_load(self.tool.theta)

    def identifying(self, board_known: bool) -> bool:
        """True while the identification motion runs: it starts only while no board is known (the controller
        waits for perception anyway) and, once started, runs to its end (time counted by :meth:`identify_reference`)."""
        t = self.identify_t_s
        return t < self.p.identify_s and (t > 0.0 or not board_known)

    def identify_reference(self, R_hold: np.ndarray, dt_s: float, R_ref: np.ndarray, twist: np.ndarray,
                           accel: np.ndarray) -> None:
        """The reference's orientation ``R_ref`` (3, 3), angular twist and acceleration (``twist[3:]``,
        ``accel[3:]``) at this tick of the roll about the pad normal ``R_hold[:, 2]`` (the position is held)."""
        self.identify_t_s += dt_s
        # out and back once, a = A (1 - cos(w t))^2 / 4: at rest and without acceleration at both ends (a sine
        # starts at full speed, a step of A w in the reference's angular velocity), at most 0.65 A w fast
        # (1.0 rad/s over 2 s for 0.5 rad)
        T, A = self.p.identify_s, self.p.identify_roll_rad
        w = 2.0 * math.pi / T
        t = min(self.identify_t_s, T)
        c, s = math.cos(w * t), math.sin(w * t)
        a, da, dda = 0.25 * A * (1.0 - c) ** 2, 0.5 * A * w * (1.0 - c) * s, 0.5 * A * w * w * (s * s + (1.0 - c) * c)
        if t >= T:
            a = da = dda = 0.0
        c, s = math.cos(a), math.sin(a)
        Rz = self._Rz
        Rz[0, 0], Rz[0, 1], Rz[1, 0], Rz[1, 1] = c, -s, s, c
        np.matmul(R_hold, Rz, out=R_ref)
        axis = R_hold[:, 2]
        twist[3:] = axis * da
        accel[3:] = axis * dda

    def estimate(self) -> ArmEstimate:
        """What was estimated, for the status (and from it the report)."""
        t, c = self.tool, self.correction
        return ArmEstimate(tool_fitted=t.valid, tool_mass_kg=t.mass_kg if t.valid else 0.0,
                           tool_com_m=[float(x) for x in t.com_flange_m] if t.valid else [],
                           tool_fit_residual_nm=t.residual_rms_nm if t.valid else 0.0,
                           correction_nm=[float(x) for x in c.c], residual_nm=[float(x) for x in c.z],
                           warning=c.warning, tool_com_unobserved=t.unobserved if t.valid else 0)
