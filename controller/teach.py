"""Teach mode: the arm hand-guided, no stiffness, light damping, the guards on (``lamps teach``).

:class:`TeachCore` answers robot states as :class:`~controller.core.ControllerCore` does, so
:class:`~controller.service.ControllerService` runs it unchanged, on the simulator and on the real robot's
adapter alike. Per tick, with the pad twist ``V = J dq`` (6,)::

    F   = -D V + F_speed                       D = diag(d_t I3, d_r I3); F_speed brakes above max_speed_m_s
    tau = J^T F - d_j dq + C(q, dq) dq [+ g(q)] gravity only when the robot does not add it itself

then :func:`~controller.control.limit_kernels.limit_torque`: the joint-limit repulsion, the joint-speed brake
(``[controller.limits]``, as while wiping) and the torque rate and absolute limits. There is no pose error and
no skill: whatever force the operator's hand puts on the tool moves it, against the damping and the arm's
inertia. A contact force above ``[controller.teach] force_cap_n`` (filtered), an e-stop or a lost robot is a
halt: the arm holds the joint pose of that moment, ``tau = M (k (q_h - q) - 2 sqrt(k) dq) [+ g]``
(``k = hold_1_s^2``), until the e-stop is released (FAULT stays until the run ends).

What is not watched: the disturbance watch of the skill (:class:`~controller.control.watch.DisturbanceWatch`)
is off, since the hand's push is exactly a joint torque the command does not explain.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np

from arm.robot_model import RobotModel
from interfaces.messages import Phase

from .control.force import NormalForceRegulator
from .control.impedance import Kinematics
from .control.limit_kernels import limit_torque
from .control.limits import SpeedOverride, TorqueShaper, limits_from_settings, speed_excess_force
from .params import ControllerParams
from .tick_io import TickInput, TickOutput, TickStatus, conclude


class _NoChain:
    """The executor's chain slot the real-time loop hands a planner thread to: nothing plans in teach mode."""

    background = None


class TeachPhase:
    """What the service asks of an executor, for the teach mode: TEACH, FAULT (latched) or ESTOP (released by
    :meth:`clear`). No stains, no skill, no MP; the pad is never "down" for a stop (nothing to lift: the
    operator holds it)."""

    current_mp = ""
    stain_id = -1
    stains_fresh = False
    pad_down = False

    def __init__(self) -> None:
        self.phase = Phase.TEACH
        self.reason = ""
        self.counters: Counter[str] = Counter()
        self.chain = _NoChain()
        self._fault: str | None = None

    @property
    def halted(self) -> bool:
        return self.phase != Phase.TEACH

    def fault(self, reason: str) -> None:
        if self._fault is None:
            self.counters["faults"] += 1
            self._fault = reason
        if self.phase != Phase.ESTOP:
            self.phase, self.reason = Phase.FAULT, reason

    def robot_lost(self, reason: str) -> None:
        self.counters["robot_lost"] += 1
        self.phase, self.reason = Phase.FAULT, reason

    def estop(self, reason: str) -> None:
        self.counters["estops"] += 1
        self.phase, self.reason = Phase.ESTOP, reason or "e-stop"

    def clear(self) -> None:
        """An e-stop released: back to TEACH, unless a fault (force cap) latched meanwhile."""
        if self._fault is not None:
            self.phase, self.reason = Phase.FAULT, self._fault
        else:
            self.phase, self.reason = Phase.TEACH, ""

    def restart(self) -> None:
        """The robot came back: teach again from where it is, unless a fault latched."""
        self.clear()

    def set_stains(self, *_update) -> None:
        """Stains are not needed to teach."""

    def stains_stale(self, reason: str) -> None:
        """Stains are not needed to teach."""


class TeachCore:
    """The per-tick computation of teach mode (see the module docstring); the interface of
    :class:`~controller.core.ControllerCore` the service uses.

    Attributes
    ----------
    executor : TeachPhase
    normal_force_n : float
        Magnitude of the last measured contact force [N].
    """

    def __init__(self, params: ControllerParams, model: RobotModel | None = None) -> None:
        self.p = params
        self.model = model or RobotModel()
        lim = self.model.limits
        self.executor = TeachPhase()
        self.kin = Kinematics(self.model)
        self.shaper = TorqueShaper(lim.tau_max, params.limits.torque_rate_nm_per_ms * 1000.0)
        self.override = SpeedOverride(lim.dq_max, params.limits.reference_joint_speed_share)
        self.force = NormalForceRegulator(0.0, 0.0, 0.0, params.teach.force_cap_n, params.force.filter_s)
        self.trace = None
        self.time_s = 0.0
        self.normal_force_n = 0.0
        self.robot_rate_hz = 0.0
        self.mode_cap_rad_s = params.impedance.max_mode_frequency_rad_s
        self.skill_steps_capped = 0
        self._period_s = 1.0 / params.rate_hz
        self._limits = limits_from_settings(lim, params.limits)  # the repulsion and the speed brake of the tick
        n = self.model.nq
        self._tau = np.zeros(n)
        self._force = np.zeros(6)
        self._brake = np.zeros(3)
        self._q_hold: np.ndarray | None = None

    def restart(self) -> None:
        """The robot came back after a loss: start the torque ramp from zero again."""
        self.shaper.reset(None)
        self.force.reset()
        self._q_hold = None
        self.executor.restart()

    def follow_robot_rate(self, rate_hz: float) -> None:
        self.robot_rate_hz = rate_hz

    def tick(self, inp: TickInput, out: TickOutput) -> TickStatus:
        """One tick, as :meth:`ControllerCore.tick <controller.core.ControllerCore.tick>` (what became of the last
        command unused: no disturbance watch, no skill clock)."""
        t0 = time.perf_counter_ns()
        tau = self._control(inp.q_rad, inp.dq_rad_s, inp.wrench, inp.gravity_compensated, inp.dt_s, inp.tau_max_nm)
        status = conclude(out, tau, self.executor.halted, t0)
        if status == TickStatus.NON_FINITE:
            self.shaper.reset(None)
            self.executor.fault("the teach law gave non-finite torques (absurd robot state?)")
        return status

    def _control(self, q: np.ndarray, dq: np.ndarray, wrench: np.ndarray, gravity_compensated: bool, dt_s: float,
                 tau_max_nm: np.ndarray) -> np.ndarray:
        """:meth:`tick`'s torques (n,) [Nm] (an internal buffer)."""
        self.time_s += dt_s
        q = np.asarray(q, float)
        dq = np.asarray(dq, float)
        np.minimum(self.model.limits.tau_max, tau_max_nm, out=self.shaper.tau_max)
        kin = self.kin.update(q, dq)
        self._watch_force(np.asarray(wrench, float), dt_s)
        tau = self._tau
        if self.executor.halted:
            self._hold_torque(q, dq, kin, tau)
        else:
            self._q_hold = None
            teach_torque_into(kin.J, dq, self._teach_force(kin.twist), self.p.teach.joint_damping_nm_s_rad, tau)
        tau += kin.nle  # C dq + g, then g off again when the robot adds it itself
        if gravity_compensated:
            tau -= kin.g
        shaper = self.shaper
        hit = limit_torque(tau, q, dq, kin.M, kin.g, not gravity_compensated, self._limits, shaper.rec,
                           shaper.rate * min(dt_s, self._period_s))
        shaper.count(hit)
        return tau

    def _watch_force(self, wrench: np.ndarray, dt_s: float) -> None:
        """The contact force's magnitude, filtered; above the cap: FAULT (the arm holds)."""
        self.normal_force_n = float(np.linalg.norm(wrench[:3]))
        self.force.measure(self.normal_force_n, dt_s)
        if self.force.over_cap and not self.executor.halted:
            self.executor.fault(f"contact force {self.force.filtered_n:.1f} N above the teach cap "
                                f"{self.p.teach.force_cap_n:.0f} N: holding; press lighter")

    def _teach_force(self, twist: np.ndarray) -> np.ndarray:
        """(6,) wrench at the pad: the damping and, above the Cartesian speed limit, the brake."""
        t, lim = self.p.teach, self.p.limits
        f = self._force
        f[:3] = -t.damping_n_s_m * twist[:3]
        f[3:] = -t.damping_nm_s_rad * twist[3:]
        f[:3] += speed_excess_force(twist[:3], lim.max_speed_m_s, lim.speed_brake_gain_n_s_m, self._brake)
        return f

    def _hold_torque(self, q: np.ndarray, dq: np.ndarray, kin: Kinematics, out: np.ndarray) -> None:
        """Halted: a critically damped joint spring on the arm's inertia to the pose where the halt began."""
        if self._q_hold is None:
            self._q_hold = q.copy()
        k = self.p.teach.hold_1_s ** 2
        out[:] = kin.M @ (k * (self._q_hold - q) - 2.0 * self.p.teach.hold_1_s * dq)


def teach_torque_into(J: np.ndarray, dq: np.ndarray, wrench: np.ndarray, joint_damping_nm_s_rad: float,
                      out: np.ndarray) -> np.ndarray:
    """``out`` (n,) = ``J^T wrench - d_j dq`` [Nm]: the teach law's torque before the dynamics terms.

    J : (6, n) pad Jacobian (world-aligned); dq : (n,) [rad/s]; wrench : (6,) [N, Nm] at the pad, world axes;
    joint_damping_nm_s_rad : d_j.
    """
    np.dot(J.T, wrench, out=out)
    out -= joint_damping_nm_s_rad * dq
    return out
