"""The simulator as a Zenoh service: :class:`SimPort` (the arm, truth, camera) served by :mod:`robot.server`.

The ``robot/*`` protocol (lock-step and real-time timing, re-sends,
sequence matching, stale commands, the command gate, counters) is
:class:`robot.server.RobotServer`'s, the same for every robot side; the
sim adds what only a simulator has: ``sim/truth`` at ``truth_rate_hz``
(simulated time), ``camera/<name>/frame`` at the camera rate (rendered in
another process), its status on ``sim/status``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import numpy as np

from interfaces.messages import Capabilities, ServiceStatus, SimTruth
from interfaces.transforms import pose_from_transform
from robot.port import Applied, Reading, RobotPort
from robot.server import RobotServer, ServerParams
from runtime.session import ServiceNode

from .core import SimCore
from .params import SimParams
from .renderer import CameraProcess, open_camera, release_camera

log = logging.getLogger(__name__)

SERVICE = "sim"


class SimPort(RobotPort):
    """The simulated arm as a stepped robot port; its extras (truth, camera frames) after each cycle.

    substeps : physics steps per cycle, the command held over them (a robot whose interface period is longer
    than its physics step: the lbr peer at FRI 2 ms over 1 ms physics). publish_frames : a thread publishes
    each frame as the renderer finishes it; False: whoever steps the port takes them (``camera.take``), as the
    network-free cell does (:mod:`launch.local_cell`).
    """

    def __init__(self, params: SimParams, node: ServiceNode, core: SimCore, substeps: int = 1,
                 publish_frames: bool = True) -> None:
        self.publish_frames = publish_frames
        self.p = params
        self.substeps = substeps
        self.node = node
        self.keys = node.keys
        self.core = core
        self.capabilities = Capabilities(params.gravity_compensated, core.tau_max.tolist(), "sim",
                                         params.rate_hz / substeps)
        self.velocity_limits_rad_s = core.dq_max
        self.limits_model = core.model
        self._zeros = np.zeros(len(core.tau_max))
        self.camera: CameraProcess | None = None
        self._camera_thread: threading.Thread | None = None
        self._extra: Counter[str] = Counter()
        self._truth_every = max(int(round(params.rate_hz / params.truth_rate_hz)), 1)
        self._camera_every = max(int(round(params.rate_hz / params.camera.rate_hz)), 1)
        self._board_pose = pose_from_transform(core.board.T_board_to_world)
        shapes = core.dirt.shapes()  # what was drawn, not the nominal ellipses
        self._centres = [[float(v) for v in s.centre_m] for s in shapes]
        self._sizes = [float(s.size_m) for s in shapes]

    # -- the port ----------------------------------------------------------------------------------
    def activate(self) -> None:
        """Start the camera renderer (raises RuntimeError if it does not come up)."""
        if not self.p.camera.enabled:
            return
        # a new renderer (or one a campaign worker kept from its previous cell, :func:`~.renderer.keep_renderers`)
        self.camera = open_camera(self.p, self.core.board, self.core.q_start, self.core.dirt.dirt.shape)
        if not self.publish_frames:
            return
        key = self.keys.camera_frame(self.p.camera.name)
        self._camera_stop = threading.Event()
        self._camera_thread = threading.Thread(target=self.camera.serve, name="sim-camera-publisher",
                                               args=(lambda f: self.node.publish(key, f), self._camera_stop),
                                               daemon=True)
        self._camera_thread.start()

    def deactivate(self) -> None:
        """The arm is left braked where it is; nothing steps any more."""

    def read(self) -> Reading:
        """The measured state (the simulated one, or through ``[sim.plant]``'s sensors and delay)."""
        q, dq, tau, wrench = self.core.measured
        return Reading(q, dq, tau, wrench, self.core.time_ns)

    def write(self, tau_nm: np.ndarray) -> Applied:
        """``tau_nm`` (7,) [Nm] over the cycle, unless the brakes are still stopping the arm (:attr:`SimRobot.stopping
        <sim.robot.SimRobot.stopping>`): a stop once begun ends with the arm standing, so the torque the gate climbs
        from (:meth:`held_torque_nm`) is the brakes' hold, not their deceleration. Released a step into standing,
        that deceleration carried on without the brakes swung the wrist at 80 rad/s^2 and pressed the pad's edge
        into the board at 46 N in a real-time cell."""
        if self.core.robot.stopping:
            self._extra["commands_held_to_finish_a_stop"] += 1
            return self.hold()
        for _ in range(self.substeps):
            self.core.step(tau_nm)
        return Applied.TORQUES

    def hold(self) -> Applied:
        for _ in range(self.substeps):
            self.core.step_braked()
        return Applied.HELD

    def yield_hold(self, tau_nm: np.ndarray) -> Applied:
        """``tau_nm`` (7,) [Nm] on top of gravity compensation (the sim's own, at each step's pose: the robot's
        compensation when it compensates, else the true weight): no brake, no task torque; a pad pressed into the
        board is pushed back by it."""
        robot = self.core.robot
        for _ in range(self.substeps):
            self.core.step(tau_nm if self.p.gravity_compensated else tau_nm + robot.gravity())
        return Applied.YIELDED

    def held_torque_nm(self) -> np.ndarray:
        """What the arm ran on over the last step in command terms: the applied torques (the brakes' while braked),
        the compensation taken off when the sim adds it; before the first step, what holds the arm against gravity."""
        robot = self.core.robot
        if self.core.steps == 0:
            return self._zeros.copy() if self.p.gravity_compensated else robot.gravity()
        tau = np.array(robot.out.tau)
        if self.p.gravity_compensated:
            tau -= robot.compensation()
        return tau

    def after_cycle(self, lockstep: bool) -> None:
        k, n = self.core.steps, self.substeps
        if k // self._truth_every != (k - n) // self._truth_every:  # a multiple passed in this cycle's steps
            self._publish_truth()
        if self.camera is not None and k // self._camera_every != (k - n) // self._camera_every:
            if self.camera.dead:
                log.error("camera renderer process ended; the sim goes on without frames")
                self._extra["camera_renderer_died"] += 1
                self.camera.close()
                self.camera = None
                return
            if lockstep and self.p.lockstep_camera_sync and not self.camera.wait_idle(10.0):
                self._extra["camera_timeouts"] += 1
            self.camera.request(k, time.monotonic_ns(), self.core.time_ns, self.core.out.q,
                                self.core.dirt.dirt, self.core.dirt.version)

    def counters(self) -> dict[str, int]:
        counters = dict(self._extra)
        if self.core.out.arm_contact:
            counters["arm_touching_board"] = 1
        if self.core.arm_contact_steps:  # steps an arm link leaned on the board (no force sensor sees it)
            counters["arm_touching_board_steps"] = self.core.arm_contact_steps
        if self.camera is not None:
            counters.update(camera_frames=self.camera.rendered, camera_ticks_skipped=self.camera.skipped)
        return counters

    def close(self) -> None:
        if self._camera_thread is not None:
            self._camera_stop.set()
            self._camera_thread.join(5.0)
            self._camera_thread = None
        if self.camera is not None:
            release_camera(self.camera)
            self.camera = None
        try:  # the last truth, where the arm was left: what a stopped cell pressed when it stopped
            self._publish_truth()
        except Exception as exc:  # the session may already be closing; the truth is a courtesy here
            log.debug("no final truth: %s", exc)
        self.core.close()

    # -- ground truth ------------------------------------------------------------------------------
    def _publish_truth(self) -> None:
        d = self.core.dirt
        self.node.publish(self.keys.sim_truth, SimTruth(
            seq=self.core.steps, stamp_ns=time.monotonic_ns(), stain_ids=d.stain_ids,
            remaining=[float(v) for v in d.remaining()], total_dirt=d.total(),
            contact_force_n=float(self.core.out.normal_force_n), robot_time_ns=self.core.time_ns,
            centres_board_m=self._centres, sizes_m=self._sizes, T_board_to_world=self._board_pose,
            peak_force_n=self.core.take_peak_force_n()))


class SimService:
    """One simulated cell on the network: a :class:`SimPort` served by the ``robot/*`` protocol.

    ``run()`` blocks until :attr:`stop` is set or ``max_steps``.
    """

    def __init__(self, params: SimParams, node: ServiceNode, core: SimCore | None = None) -> None:
        self.p = params
        self.core = core or SimCore(params)
        self.port = SimPort(params, node, self.core)
        server_params = ServerParams(mode=params.mode, rate_hz=params.rate_hz, stale_limit_s=params.stale_limit_s,
                                     republish_s=params.lockstep_republish_s, max_steps=params.max_steps,
                                     status_rate_hz=params.status_rate_hz,
                                     speed_brake_share=params.speed_brake_share,
                                     late_damping_rad_s=params.late_damping_rad_s)
        self.server = RobotServer(self.port, node, server_params, SERVICE, node.keys.sim_status)
        self.stop = self.server.stop

    def run(self) -> int:
        """Serve until stopped; returns the number of physics steps taken."""
        try:
            self.server.run()
        finally:
            self.port.close()
        return self.core.steps

    def status(self) -> ServiceStatus:
        return self.server.status()
