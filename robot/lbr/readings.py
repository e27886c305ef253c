"""The robot's reading from the stack's states: joint velocity estimated, torques unfiltered, the pad wrench.

The stack publishes joint positions without velocities and low-passes the measured and external torques (10 Hz
by default); :class:`StateReadings` estimates the velocity from the positions
(:class:`~robot.lbr.guards.VelocityFilter`), recovers the raw torques from consecutive states
(:class:`~robot.lbr.compensation.TorqueUnfilter`), and takes the pad wrench from the external torque through our
model (:func:`~robot.lbr.rest_checks.pad_wrench`) or, with ``wrench_source = "stack"``, from the stack's estimate
brought to the pad (:func:`~robot.lbr.tip.stack_wrench_to_tcp`).
"""

from __future__ import annotations

import numpy as np

from arm.robot_model import RobotModel
from robot.port import Reading

from .compensation import TorqueUnfilter
from .guards import VelocityFilter
from .msgs import N_JOINTS, LbrState
from .params import LbrParams
from .rest_checks import pad_wrench
from .tip import stack_wrench_to_tcp

#: The most FRI cycles a message is taken to be applied for (a longer gap between states is a gap, not a rate).
MAX_CYCLES_PER_STATE = 20


class StateReadings:
    """The newest state with a new time stamp and the reading made of it.

    state : the newest :class:`~robot.lbr.msgs.LbrState` (None: none yet); sample_s : its sample time [s] (the FRI
    send period); cycles_per_state : FRI cycles between the newest two states (how long a message will be applied,
    1 to :data:`MAX_CYCLES_PER_STATE`); reading : the :class:`~robot.port.Reading` (joint order of the model, its
    fields replaced each state); ext_wrench : (6,) the pad wrench [N, Nm] the external torque explains, world axes
    (whatever ``wrench_source`` says: the rest checks use it).
    """

    def __init__(self, params: LbrParams, model: RobotModel) -> None:
        self.p = params
        self.model = model
        self.state: LbrState | None = None
        self.sample_s = 0.0
        self.cycles_per_state = 1
        self.reading = Reading(np.zeros(N_JOINTS), np.zeros(N_JOINTS), np.zeros(N_JOINTS), np.zeros(6), 0,
                               dq_estimated=True)
        self.ext_wrench = np.zeros(6)
        self._velocity = VelocityFilter(N_JOINTS, params.velocity_cutoff_hz)
        self._tau_measured = TorqueUnfilter(params.measured_torque_cutoff_hz)
        self._tau_external = TorqueUnfilter(params.external_torque_cutoff_hz)

    @property
    def passed_filtered(self) -> int:
        """How many external torques went through filtered (:attr:`TorqueUnfilter.passed_filtered`)."""
        return self._tau_external.passed_filtered

    def take(self, st: LbrState, stack_wrench: np.ndarray | None) -> float:
        """The state ``st`` (a new time stamp), with the stack's newest wrench estimate ``stack_wrench`` (6,) [N, Nm]
        in the tip frame (None: none yet); the state period [s]: the FRI's, or the controller manager's when it runs
        slower (its states come slower)."""
        prev = self.state
        period_s = st.sample_time_s if prev is None else max(st.sample_time_s, (st.stamp_ns - prev.stamp_ns) * 1e-9)
        self.cycles_per_state = min(max(round(period_s / st.sample_time_s), 1), MAX_CYCLES_PER_STATE)
        self.state, self.sample_s = st, st.sample_time_s
        r = self.reading
        r.q_rad = st.q_rad
        r.dq_rad_s = self._velocity.update(st.q_rad, st.stamp_ns).copy()
        r.tau_nm = self._tau_measured.update(st.tau_measured_nm, st.stamp_ns, st.sample_time_s).copy()
        tau_ext = self._tau_external.update(st.tau_external_nm, st.stamp_ns, st.sample_time_s)
        r.robot_time_ns = st.stamp_ns
        if self.p.wrench_source == "stack":  # the stack's estimate; the rest checks use the external torque's
            r.wrench_world = np.zeros(6) if stack_wrench is None else stack_wrench_to_tcp(
                self.model, st.q_rad, stack_wrench, self.p.wrench_force_threshold_n, self.p.wrench_torque_threshold_nm)
        self.ext_wrench = pad_wrench(self.model, st.q_rad, tau_ext)
        if self.p.wrench_source != "stack":
            r.wrench_world = self.ext_wrench
        return period_s
