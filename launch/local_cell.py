"""``lamps up --no-network``: the whole lock-step cell in one process, stepped without a network.

A campaign measures the skill, not the transport: this cell runs the same
services as ``lamps up`` (the compose file's sim, controller, perception and
recorder, with the same environment, so the same configuration) built from
the same classes, :class:`~sim.service.SimPort` served by
:class:`~robot.server.RobotServer`, :class:`~controller.service.ControllerService`,
:class:`~perception.service.PerceptionService` reading
:class:`~perception.sources.ZenohSource`, :class:`~launch.record.Recorder`,
each on a :class:`~runtime.local_bus.LocalNode` instead of a Zenoh session
(same codec, same readers and counters). One thread steps them in the lock-step
order of the networked cell: state k to the controller
(:meth:`~controller.service.ControllerService.answer`), its command to the
robot side (:meth:`~robot.server.RobotServer.lockstep_cycle`: gate, physics step,
truth, camera request, state k + 1). A frame asked for at step k reaches
perception :data:`FRAME_LATENCY_S` of robot time later (the renderer's process
works meanwhile) and its stains reach the controller at its next tick, so a
seed always gives the same run. Perception's clock is the robot's.

The run ends as ``lamps up`` ends it (:class:`~launch.run_end.RunEnd`: DONE held
2.5 s, a fault held 5 s, both in robot time here; ``--max-duration`` (wall),
Ctrl-C, after which the controller lifts the pad first), and the run folder
gets the same ``run.json``, ``recording.mcap`` and ``report.json``; the
recording's ``log_time`` is the robot's clock from the wall time the cell
started, so a wait of the one loop (a frame, a loaded machine) is no silence
of a service. Lock-step only, the
simulator only (``--robot sim``): real time and a real robot need the network.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

from lampskit.errors import LampsError

from .run_end import RunEnd

log = logging.getLogger("launch.local_cell")

#: Robot time from a camera frame's request (the state it shows) to perception taking it [s]: about what the
#: networked lock-step cell takes (render, put, decode) at its speed on this machine.
FRAME_LATENCY_S = 0.05
#: Services the cell needs from the compose file (the recorder is made here, not read).
NEEDED = ("sim", "controller", "perception")
#: After a stop with the pad on the board, step at most this many robot seconds while the controller lifts it.
LIFT_S = 8.0


class LocalCellError(LampsError):
    """Why the network-free cell cannot run (a missing service, a realtime mode, a robot that is not the sim)."""


def _environments(services, extra: dict[str, str]) -> dict[str, dict[str, str]]:
    """Service name -> its environment as ``lamps up`` starts it: this process's, the compose file's for it, and
    ``extra`` (the board of a --board file)."""
    import os

    envs = {s.name: {**os.environ, **s.environment, **extra} for s in services}
    missing = [n for n in NEEDED if n not in envs]
    if missing:
        raise LocalCellError(f"--no-network needs the compose services {', '.join(NEEDED)}; "
                             f"{', '.join(missing)} not active (the robot side must be the sim: --robot sim)")
    return envs


class _Cell:
    """The services of one cell on one bus, built from their compose environments as their commands build them."""

    def __init__(self, envs: dict[str, dict[str, str]], out: Path) -> None:
        from arm.joint_dynamics import joint_dynamics_from_config
        from arm.robot_model import RobotModel
        from controller.cli import load_runnable_skill
        from controller.core import ControllerCore
        from controller.params import ControllerParams
        from controller.service import ControllerService
        from perception.params import PerceptionParams
        from perception.service import PerceptionService
        from perception.sources import ZenohSource
        from robot.server import RobotServer, ServerParams
        from runtime.config import load_config
        from runtime.local_bus import LocalBus, LocalNode, LocalSession
        from sim.core import SimCore
        from sim.params import SimParams
        from sim.service import SimPort

        from .record import Recorder

        cfg = {name: load_config(None, env) for name, env in envs.items()}
        sim_p = SimParams.from_table(cfg["sim"].table("sim"))
        ctrl_p = ControllerParams.from_table(cfg["controller"].table("controller"))
        perc_p = PerceptionParams.from_table(cfg["perception"].table("perception"))
        if sim_p.mode != "lockstep" or ctrl_p.mode != "lockstep":
            raise LocalCellError(f"--no-network runs lock-step only (sim {sim_p.mode}, controller {ctrl_p.mode})")
        self.settings = cfg["controller"].zenoh
        self.keys = self.settings.keys
        self.bus = LocalBus()
        self.t0_wall_ns = time.time_ns()
        self.sim = None
        # the recording's clock is the robot's (from the wall time the cell started): a loop that waits for a frame
        # or a slow machine stops the robot's clock too, so a pause is not a silence of the services
        self.recorder = Recorder(LocalSession(self.bus), self.keys, out, clock=self._clock_ns)
        self.nodes = [LocalNode(n, self.bus, self.settings).__enter__() for n in ("sim", "controller", "perception",
                                                                                   "launcher")]
        sim_node, ctrl_node, perc_node, self.watch = self.nodes
        self.sim = SimCore(sim_p, RobotModel(joints=joint_dynamics_from_config(None, envs["sim"])))
        self.port = SimPort(sim_p, sim_node, self.sim, publish_frames=False)
        self.server = RobotServer(self.port, sim_node, ServerParams(
            mode="lockstep", rate_hz=sim_p.rate_hz, stale_limit_s=sim_p.stale_limit_s,
            republish_s=sim_p.lockstep_republish_s, status_rate_hz=sim_p.status_rate_hz,
            speed_brake_share=sim_p.speed_brake_share), "sim", self.keys.sim_status)
        skill = load_runnable_skill(ctrl_p.skill)
        model = RobotModel(joints=joint_dynamics_from_config(None, envs["controller"]))
        self.controller = ControllerService(ctrl_p, ctrl_node, ControllerCore(ctrl_p, skill, model))
        self.perception = PerceptionService(perc_p, perc_node, ZenohSource(perc_node, perc_p.camera))
        self.camera_key = self.keys.camera_frame(sim_p.camera.name)
        self.sim_node = sim_node
        self.latency_steps = max(int(round(FRAME_LATENCY_S * sim_p.rate_hz)), 1)

    def _clock_ns(self) -> int:
        return self.t0_wall_ns + (self.sim.time_ns if self.sim is not None else 0)

    def close(self) -> Path:
        """Everything stopped and closed; the recording finished (its path)."""
        try:
            self.port.close()
        finally:
            for node in self.nodes:
                node.close()
        return self.recorder.close()


def run(services, extra_env: dict[str, str], out: Path, robot_id: str, skill: Path, options: dict,
        max_duration_s: float, stop_requested: threading.Event,
        progress: Callable[[float], None] | None = None) -> str:
    """Run the cell in ``out`` until it ends; writes ``run.json`` and the recording (not the report); returns why
    it ended. ``progress(elapsed_s, status, truth, stains, first_dirt)`` is called every 2 s (wall)."""
    from interfaces.messages import ControllerStatus, SimTruth, Stains

    t_start = time.monotonic()
    try:
        cell = _Cell(_environments(services, extra_env), out)
    except (LampsError, OSError) as exc:  # a configuration or skill the services' commands would refuse too
        raise LocalCellError(f"the cell cannot start: {exc}") from None
    outcome, why, steps = "failed", "the cell did not start", 0
    try:
        keys = cell.keys
        status = cell.watch.latest(keys.controller_status, ControllerStatus)
        truth = cell.watch.latest(keys.sim_truth, SimTruth)
        stains = cell.watch.latest(keys.perception_stains, Stains)
        cell.port.activate()  # the camera's renderer process
        outcome, why = _step(cell, status, truth, stains, max_duration_s, stop_requested, progress, t_start)
        steps = cell.server.steps
    except LampsError as exc:
        outcome, why = "failed", str(exc)
    except RuntimeError as exc:  # the camera's renderer did not come up or died
        outcome, why = "failed", f"sim: {exc}"
    finally:
        # on the recording's clock (the robot's, from the wall time the cell started), as the report reads them
        # against its log times: a cell faster than the wall stopped at a wall time its recording had not reached,
        # and the report took the phase before it (a DONE cell read as mid-wipe)
        stopping_ns = cell._clock_ns()
        try:
            cell.server.housekeeping()
        finally:
            final = cell.close()
        codes = {n: (0 if outcome != "failed" else 1) for n in (*NEEDED, "recorder")}
        record = {"outcome": outcome, "why": why, "stopping_wall_ns": stopping_ns, "ended_wall_ns": cell._clock_ns(),
                  "duration_s": time.monotonic() - t_start, "services": codes, "key_prefix": f"lamps/{robot_id}",
                  "skill": str(skill), "options": options, "network": "none", "steps": steps}
        from lampskit.atomic import write_text_atomic

        write_text_atomic(out / "run.json", json.dumps(record, indent=1) + "\n")
        log.info("recording %s", final)
    return why


def _step(cell: _Cell, status, truth, stains, max_duration_s: float, stop_requested: threading.Event,
          progress, t_start: float) -> tuple[str, str]:
    """Step the cell until it ends: (outcome for run.json, why)."""
    ctrl, server, port, perception, sim = cell.controller, cell.server, cell.port, cell.perception, cell.sim
    assert sim is not None  # built with the cell
    states = ctrl.lockstep_states()
    commands = server.start_lockstep()
    end = RunEnd()
    st = tr = sn = None
    first_dirt = None
    frame_due = -1  # the step at which the frame being rendered reaches perception (-1: none)
    seen_requests = 0
    next_look = 0.0
    ending: tuple[str, str] | None = None
    lift_until = float("inf")  # set with ``ending``
    while True:
        state = states.get(0.0)
        if state is not None:
            ctrl.answer(state)
        cmd = commands.get(0.0)
        if cmd is None:
            raise LocalCellError(f"the controller gave no answer to state {server.steps} "
                                 f"(phase {ctrl.core.executor.phase}: {ctrl.core.executor.reason})")
        server.lockstep_cycle(cmd)
        robot_s = sim.time_ns * 1e-9
        camera = port.camera
        if camera is not None and camera.requested > seen_requests:
            seen_requests = camera.requested
            frame_due = server.steps + cell.latency_steps
        if frame_due >= 0 and server.steps >= frame_due:
            frame_due = -1
            frame = camera.take(10.0) if camera is not None else None
            if frame is not None:
                cell.sim_node.publish(cell.camera_key, frame)
            perception.serve_once(perception.source.read(), robot_s)
        elif server.steps % 10 == 0:
            perception.serve_once(None, robot_s)
        if ending is not None:  # stopping: the controller lifts the pad first
            if ctrl.exit_now() or robot_s > lift_until:
                return ending
            continue
        if server.steps % 50:
            continue
        now = time.monotonic()
        server.housekeeping()
        st = status.take() or st
        tr = truth.take() or tr
        sn = stains.take() or sn
        if first_dirt is None and tr is not None and tr.total_dirt > 0:
            first_dirt = tr.total_dirt
        if st is not None and (ended := end.update(st.phase, st.reason, robot_s, robot_s)):
            return ended
        if stop_requested.is_set():
            ending = ("stopped", "stopped by the user (Ctrl-C)")
        elif now - t_start > max_duration_s:
            ending = ("timeout", f"not finished after --max-duration {max_duration_s:g} s")
        if ending is not None:
            ctrl.stop.set()
            lift_until = robot_s + LIFT_S
            if ctrl.exit_now():
                return ending
        if progress is not None and now >= next_look:
            next_look = now + 2.0
            progress(now - t_start, st, tr, sn, first_dirt)
