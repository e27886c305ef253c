"""The two ways ``lamps teach`` runs the arm: the simulated cell in one process, or a teach controller on the network.

Both run :class:`~controller.service.ControllerService` around :class:`~controller.teach.TeachCore` and record
``robot/state`` (what the robot reports, not what the controller thinks) with a :class:`PathRecorder`.

- :func:`run_local` (``--no-network``): the sim (:class:`~sim.service.SimPort` behind
  :class:`~robot.server.RobotServer`) with the scripted hand (``[sim.hand]``, :mod:`sim.hand`), the controller
  and the recorder on one in-process bus, stepped in lock-step as :mod:`launch.local_cell` steps a cell; no
  camera, no perception. Deterministic for its hand script.
- :func:`run_network`: the controller in teach mode as a Zenoh peer or client of the cell (``[zenoh]``,
  ``--connect``), in the configured mode (``realtime`` for a real robot), with the robot side running apart:
  ``lamps robot --backend lbr`` for the real iiwa, or ``lamps sim``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np

from lampskit.errors import LampsError

log = logging.getLogger("launch.teach")


class TeachError(LampsError):
    """Why teaching could not run or its demonstration is not written (one line)."""


class PathRecorder:
    """Joint positions of the robot's states at about ``rate_hz``, on the robot's clock; the pad path by forward
    kinematics when asked (:meth:`pad_path`)."""

    def __init__(self, rate_hz: float) -> None:
        self.period_ns = int(round(1e9 / rate_hz))
        self.t_ns: list[int] = []
        self.q: list[np.ndarray] = []
        self.last_ns: int | None = None
        self.first_ns: int | None = None

    def add(self, robot_time_ns: int, q_rad) -> None:
        if self.first_ns is None:
            self.first_ns = robot_time_ns
        if self.last_ns is not None and robot_time_ns - self.last_ns < self.period_ns - self.period_ns // 10:
            return
        self.last_ns = robot_time_ns
        self.t_ns.append(robot_time_ns)
        self.q.append(np.array(q_rad, float))

    @property
    def duration_s(self) -> float:
        return (self.t_ns[-1] - self.t_ns[0]) * 1e-9 if self.t_ns else 0.0

    def pad_path(self, model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t (T,) [s] from the first sample, p (T, 3) [m], quaternions (T, 4) wxyz) of the pad centre, base frame."""
        from interfaces.transforms import quat_wxyz_from_matrix

        t = (np.array(self.t_ns, dtype=np.int64) - self.t_ns[0]) * 1e-9
        p, quat = np.empty((len(t), 3)), np.empty((len(t), 4))
        for k, q in enumerate(self.q):
            p[k], R = model.tcp_pose(q)
            quat[k] = quat_wxyz_from_matrix(R)
        flip = np.r_[False, np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0]  # one hemisphere, continuous
        quat[np.logical_xor.accumulate(flip)] *= -1.0
        return t, p, quat


def _controller(ctrl_p, node, model):
    from controller.service import ControllerService
    from controller.teach import TeachCore

    return ControllerService(ctrl_p, node, TeachCore(ctrl_p, model))


def run_local(sim_p, ctrl_p, envs_joints, recorder: PathRecorder, duration_s: float,
              stop_requested: threading.Event, progress: Callable[[str], None] | None = None) -> str:
    """Teach in the simulated cell, network-free, for ``duration_s`` of robot time (or until stopped); the states
    go to ``recorder``. Returns why it ended; raises :class:`TeachError` on a FAULT or ESTOP (the demonstration
    is then not to be written)."""
    from arm.robot_model import RobotModel
    from interfaces.messages import Phase, RobotState
    from robot.server import RobotServer, ServerParams
    from runtime.local_bus import LocalBus, LocalNode
    from sim.core import SimCore
    from sim.service import SimPort

    if sim_p.mode != "lockstep" or ctrl_p.mode != "lockstep":
        raise TeachError(f"--no-network runs lock-step only (sim {sim_p.mode}, controller {ctrl_p.mode})")
    bus = LocalBus()
    nodes = [LocalNode(n, bus).__enter__() for n in ("sim", "controller", "teach")]
    sim_node, ctrl_node, watch = nodes
    try:
        core = SimCore(sim_p, RobotModel(joints=envs_joints))
    except LampsError as exc:
        for n in nodes:
            n.close()
        raise TeachError(f"the sim cannot start: {exc}") from None
    port = SimPort(sim_p, sim_node, core, publish_frames=False)
    try:
        server = RobotServer(port, sim_node, ServerParams(
            mode="lockstep", rate_hz=sim_p.rate_hz, stale_limit_s=sim_p.stale_limit_s,
            republish_s=sim_p.lockstep_republish_s, status_rate_hz=sim_p.status_rate_hz,
            speed_brake_share=sim_p.speed_brake_share,
            # the hand moves and presses the arm here, not a controller: the teach's own force cap holds it, and
            # the robot side's press-speed and force yields (limits against a controller) would fight the hand
            press_speed_limit_m_s=0.0, force_cap_n=0.0), "sim", sim_node.keys.sim_status)
        ctrl = _controller(ctrl_p, ctrl_node, RobotModel(joints=envs_joints))
        states_seen = watch.inbox(watch.keys.robot_state, RobotState, maxlen=16)
        states = ctrl.lockstep_states()
        commands = server.start_lockstep()
        next_note = 0.0
        while True:
            state = states.get(0.0)
            if state is not None:
                ctrl.answer(state)
            cmd = commands.get(0.0)
            if cmd is None:
                raise TeachError(f"the teach controller gave no answer to state {server.steps}")
            server.lockstep_cycle(cmd)
            while (seen := states_seen.get(0.0)) is not None:
                recorder.add(seen.robot_time_ns, seen.q_rad)
            robot_s = core.time_ns * 1e-9
            ex = ctrl.core.executor
            if ex.phase != Phase.TEACH:
                raise TeachError(f"{ex.phase} at {robot_s:.2f} s: {ex.reason}")
            if robot_s >= duration_s:
                return f"--duration {duration_s:g} s of robot time"
            if server.steps % 200 == 0:
                server.housekeeping()
                if stop_requested.is_set():
                    return "stopped by the user"
                if progress is not None and robot_s >= next_note:
                    next_note = robot_s + 5.0
                    progress(f"[teach {robot_s:5.1f} s] pad force {ctrl.core.normal_force_n:4.1f} N, "
                             f"{len(recorder.t_ns)} samples")
    finally:
        try:
            port.close()
        finally:
            for n in nodes:
                n.close()


def run_network(settings, ctrl_p, model, recorder: PathRecorder, duration_s: float | None,
                stop_requested: threading.Event, progress: Callable[[str], None] | None = None,
                wait_s: float = 30.0) -> str:
    """Teach through the cell's network: the teach controller serves the robot side that publishes
    ``robot/state`` under ``settings``' prefix, until stopped or ``duration_s`` of robot time from the first
    recorded state. Raises :class:`TeachError` when no state comes within ``wait_s`` [s], or on a halt."""
    from interfaces.messages import Phase, RobotState
    from runtime.session import ServiceNode

    try:
        node = ServiceNode("controller", settings).__enter__()
    except Exception as exc:  # zenoh raises its own error type for a bad or busy endpoint
        raise TeachError(f"cannot open the Zenoh session ({exc})") from None
    try:
        ctrl = _controller(ctrl_p, node, model)
        seen = node.inbox(node.keys.robot_state, RobotState, maxlen=256)
        thread = threading.Thread(target=ctrl.run, name="teach-controller", daemon=True)
        thread.start()
        t0 = time.monotonic()
        next_note = 0.0
        why = "stopped by the user"
        try:
            while not stop_requested.is_set():
                state = seen.get(0.05)
                while state is not None:
                    recorder.add(state.robot_time_ns, state.q_rad)
                    state = seen.get(0.0)
                ex = ctrl.core.executor
                if ex.phase != Phase.TEACH:
                    raise TeachError(f"{ex.phase}: {ex.reason}")
                if recorder.first_ns is None and time.monotonic() - t0 > wait_s:
                    raise TeachError(f"no robot state on {node.keys.robot_state} within {wait_s:g} s: is the robot "
                                     "side running and armed, and --connect / [zenoh] pointing at it?")
                if duration_s is not None and recorder.duration_s >= duration_s:
                    why = f"--duration {duration_s:g} s"
                    break
                if progress is not None and recorder.t_ns and time.monotonic() >= next_note:
                    next_note = time.monotonic() + 5.0
                    progress(f"[teach {recorder.duration_s:5.1f} s] contact force {ctrl.core.normal_force_n:4.1f} N, "
                             f"{len(recorder.t_ns)} samples; Enter or Ctrl-C stops")
        finally:
            ctrl.stop.set()
            thread.join(10.0)
        return why
    finally:
        node.close()
