"""The simulated cell without any networking: board, dirt, arm, one step at a time.

:class:`SimCore` is what the service shell (:mod:`sim.service`) drives and
what benchmarks time alone: ``step(torques)`` (or ``step_braked()``)
advances physics by one period, reads the arm back and lets the pad wipe
the dirt under it.
"""

from __future__ import annotations

import numpy as np
import pybullet as pb

from arm.robot_model import RobotModel
from interfaces.errors import ConfigError

from .board import Board, board_from_params, check_board, start_configuration, wipe_region
from .camera import camera_pose
from .dirt import DirtGrid, random_stains, stains_from_specs
from .hand import hand_from_params
from .params import SimParams
from .plant import Measurement, plant_joints, plant_urdf
from .robot import Readout, SimRobot
from .start_view import start_view_problem
from .wiping import PadWiper
from .world import build_world


def make_stains(params: SimParams, board: Board):
    """The stains of the config: explicit ``[[sim.dirt.stain]]`` tables, else random from the seed."""
    lo, hi = wipe_region(board, params.dirt.margin_m)
    if params.dirt.stain:
        return stains_from_specs(params.dirt.stain, lo, hi)
    rng = np.random.default_rng(params.seed)
    return random_stains(rng, params.dirt.stains, params.dirt.stain_size_m, lo, hi)


class SimCore:
    """Physics, dirt and robot of one cell. Raises :class:`ConfigError` for an impossible set-up.

    ``model`` (default ``RobotModel()``) gives the limits, the start pose and, in
    ``model.joints``, the rotor inertia and friction the simulated drives get unless
    ``[sim.plant]`` gives them its own; the arm's links and tool are the description's
    changed by ``[sim.plant]`` (:mod:`sim.plant`), the controller's model is never.

    Attributes
    ----------
    board : Board
    dirt : DirtGrid
    robot : SimRobot
    q_start : (7,) start joint positions [rad]
    steps : physics steps taken
    model : the description the arm was built from (limits, start pose)
    joints : the simulated drives' rotor inertia and friction
    measured : (q, dq, tau, wrench) as the robot's sensors report them (delayed, biased, noisy per the plant)
    wiper : the pad's removal of :attr:`dirt` from :attr:`board`
    """

    def __init__(self, params: SimParams, model: RobotModel | None = None) -> None:
        self.params = params
        self.model = model = model or RobotModel()  # the robot side's limits use it too (its thread)
        plant = params.plant
        self.joints = plant_joints(plant, model.joints)
        self.tau_max = model.limits.tau_max.copy()
        self.dq_max = model.limits.dq_max.copy()
        self.board = board_from_params(params.board)
        check_board(self.board, params.dirt.margin_m, model)
        self.dirt = DirtGrid(self.board.size_m, params.dirt.cell_m, make_stains(params, self.board), params.seed)
        self.T_camera_to_world = None
        if params.camera.enabled:
            try:
                self.T_camera_to_world = camera_pose(params.camera, self.board)
            except ValueError as exc:
                raise ConfigError(f"[sim.camera] {exc}") from None
        if params.start_q_rad is not None:
            self.q_start = np.array(params.start_q_rad)
            lo, hi = model.limits.q_min, model.limits.q_max
            bad = [i + 1 for i in range(7) if not lo[i] <= self.q_start[i] <= hi[i]]
            if bad:
                raise ConfigError(f"[sim] start_q_rad: joint(s) {bad} outside the description's limits "
                                  f"{np.round(lo, 3).tolist()} .. {np.round(hi, 3).tolist()} rad")
        else:
            camera_m = None if self.T_camera_to_world is None else self.T_camera_to_world[:3, 3]
            self.q_start = start_configuration(self.board, params.start_standoff_m, model, params.dirt.margin_m,
                                               camera_m)
        if self.T_camera_to_world is not None:
            why = start_view_problem(self.board, self.q_start, self.T_camera_to_world[:3, 3], model)
            if why is not None:
                raise ConfigError(f"impossible start: {why} (the controller holds the arm until it sees the board; "
                                  f"move the start pose or the camera: [sim] start_q_rad, [sim.camera])")
        self.client = pb.connect(pb.DIRECT)
        try:
            urdf = None if plant.body_is_described else plant_urdf(plant)
            self.world = build_world(self.client, self.board, params.contact, self.q_start, params.dt_s,
                                     urdf_text=urdf)
            self._check_start_clear()
        except Exception:
            pb.disconnect(self.client)
            raise
        load = None
        if not plant.load_is_true:
            (m_true, c_true), (m_load, c_load) = plant.true_tool(), plant.load_data()
            load = (m_true, np.array(c_true), m_load, np.array(c_load))
        self.robot = SimRobot(self.world, self.tau_max, self.board.normal_world, params.gravity_compensated,
                              self.joints, params.dt_s, load)
        self._measurement = None if plant.measurement_is_exact else Measurement(plant)
        self.measured = self._measure(self.robot.out)
        self.steps = 0
        self.peak_force_n = 0.0  # the largest normal force since the last take_peak_force_n() [N]
        self.arm_contact_steps = 0  # steps in which a link other than the eraser touched the board
        try:
            self.hand = hand_from_params(params.hand, self.robot.out.tcp_R)  # holds the tool as it starts
        except ConfigError:
            self.close()
            raise
        self.wiper = PadWiper(self.board, self.dirt, params.dirt, params.dt_s)

    def _check_start_clear(self) -> None:
        hits = pb.getClosestPoints(self.world.robot, self.world.board, 0.0, physicsClientId=self.client)
        if any(h[8] < -1e-4 for h in hits):
            raise ConfigError("impossible start: the arm's start pose penetrates the board "
                              "(check [sim] start_q_rad or the board pose)")

    @property
    def out(self) -> Readout:
        return self.robot.out

    @property
    def time_ns(self) -> int:
        """Simulated time [ns] of the current state."""
        return int(round(self.steps * 1e9 / self.params.rate_hz))

    def step(self, tau_nm: np.ndarray) -> Readout:
        """Apply torques (7,) [Nm] (validated), step once, read, wipe. The hand (if a script is set) acts on the pad
        through the step, from the last readout."""
        self._hand_acts()
        self.robot.write(tau_nm)
        return self._advance()

    def step_braked(self) -> Readout:
        """Brake (hold the position, no torques), step once, read, wipe; the hand acts as in :meth:`step`."""
        self._hand_acts()
        self.robot.brake()
        return self._advance()

    def _hand_acts(self) -> None:
        """The hand's wrench on the pad over the coming step (if a script is set), from the last readout."""
        if self.hand is not None:
            o = self.robot.out
            self.robot.external_wrench[:] = self.hand.update(self.steps * self.params.dt_s, o.tcp_p, o.tcp_v, o.tcp_R,
                                                             o.tcp_w)

    def _advance(self) -> Readout:
        """Step the physics once with what was written, read back, count, wipe."""
        self.robot.step()
        self.steps += 1
        out = self.robot.read()
        self.measured = self._measure(out)
        if out.normal_force_n > self.peak_force_n:
            self.peak_force_n = out.normal_force_n
        if out.arm_contact:
            self.arm_contact_steps += 1
        if self.steps % self.wiper.every_steps == 0:
            self.wiper.wipe(out)
        return out

    def _measure(self, o: Readout) -> tuple[np.ndarray, ...]:
        if self._measurement is None:
            return o.q, o.dq, o.tau, o.wrench
        return self._measurement.measure(o.q, o.dq, o.tau, o.wrench)

    def take_peak_force_n(self) -> float:
        """The largest normal force of the pad on the board [N] over the steps since the last call; restarts."""
        peak, self.peak_force_n = self.peak_force_n, self.robot.out.normal_force_n
        return max(peak, self.peak_force_n)

    def close(self) -> None:
        if self.client is not None:
            pb.disconnect(self.client)
            self.client = None
