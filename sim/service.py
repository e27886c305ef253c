"""The simulator as a Zenoh service: real-time and lock-step loops around :class:`~sim.core.SimCore`.

Publishes ``robot/state`` every step, ``sim/truth`` at ``truth_rate_hz``
(simulated time), ``camera/<name>/frame`` at the camera rate (rendered in
another process) and ``sim/status`` (counters and loop timing) at
``status_rate_hz`` (wall time). Reads ``robot/command``:

* lock-step: state k is published, the sim steps once a valid command with
  ``seq == k`` arrives (state k is re-sent every ``lockstep_republish_s``
  until then), so a run is deterministic for a seed;
* real-time: 1 kHz on absolute wall-clock deadlines, the newest command is
  held; with no command yet, a ``hold`` command, or a command older than
  ``stale_limit_s``, the arm brakes and holds. Overruns are counted and the
  missed periods skipped, never caught up in a burst.

Bad commands never reach the physics: undecodable or non-finite payloads
are dropped, wrong vector lengths dropped, torques over the limits clipped;
each counted by reason in the status.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

import numpy as np

from interfaces.messages import Capabilities, LoopTiming, RobotState, ServiceStatus, SimTruth, TorqueCommand
from interfaces.session import ServiceNode
from interfaces.transforms import pose_from_transform

from .commands import HOLD, CommandGate
from .core import SimCore
from .params import SimParams
from .renderer import CameraProcess

log = logging.getLogger(__name__)

SERVICE = "sim"
_TIMING_WINDOW = 4096


class _Timing:
    """Ring buffers of the loop's period and its parts [us]."""

    def __init__(self) -> None:
        self.period = np.zeros(_TIMING_WINDOW)
        self.read = np.zeros(_TIMING_WINDOW)
        self.update = np.zeros(_TIMING_WINDOW)
        self.write = np.zeros(_TIMING_WINDOW)
        self.n = 0
        self.overruns = 0

    def add(self, period_us: float, read_us: float, update_us: float, write_us: float) -> None:
        i = self.n % _TIMING_WINDOW
        self.period[i], self.read[i], self.update[i], self.write[i] = period_us, read_us, update_us, write_us
        self.n += 1

    def summary(self) -> LoopTiming:
        m = min(self.n, _TIMING_WINDOW)
        if m == 0:
            return LoopTiming(overruns=self.overruns)
        p = self.period[:m]
        return LoopTiming(float(np.percentile(p, 50)), float(np.percentile(p, 99)), float(p.max()),
                          float(np.percentile(self.read[:m], 99)), float(np.percentile(self.update[:m], 99)),
                          float(np.percentile(self.write[:m], 99)), self.n, self.overruns)


class SimService:
    """One simulated cell on the network. ``run()`` blocks until :attr:`stop` is set or ``max_steps``."""

    def __init__(self, params: SimParams, node: ServiceNode, core: SimCore | None = None) -> None:
        self.p = params
        self.node = node
        self.keys = node.keys
        self.core = core or SimCore(params)
        self.counters: Counter[str] = Counter()
        self.gate = CommandGate(self.core.tau_max, self.counters)
        self.caps = Capabilities(params.gravity_compensated, self.core.tau_max.tolist(), "sim")
        self.stop = threading.Event()
        self.timing = _Timing()
        self.camera: CameraProcess | None = None
        self._camera_thread: threading.Thread | None = None
        self._truth_every = max(int(round(params.rate_hz / params.truth_rate_hz)), 1)
        self._camera_every = max(int(round(params.rate_hz / params.camera.rate_hz)), 1)
        self._status_period_s = 1.0 / params.status_rate_hz
        self._next_status = 0.0
        self._board_pose = pose_from_transform(self.core.board.T_board_to_world)
        shapes = self.core.dirt.shapes()  # what was drawn, not the nominal ellipses
        self._centres = [[float(v) for v in s.centre_m] for s in shapes]
        self._sizes = [float(s.size_m) for s in shapes]
        self._commands_key = self.keys.robot_command
        self.braked = True

    # -- lifecycle ---------------------------------------------------------------------------------
    def run(self) -> int:
        """Serve until stopped; returns the number of physics steps taken."""
        try:
            self._start_camera()
            if self.p.mode == "lockstep":
                self._run_lockstep()
            else:
                self._run_realtime()
        finally:
            self._publish_status(force=True)
            self.close()
        return self.core.steps

    def _start_camera(self) -> None:
        if not self.p.camera.enabled:
            return
        camera = CameraProcess(self.p, self.core.board, self.core.q_start, self.core.dirt.dirt.shape)
        camera.start()  # closes itself and raises RuntimeError if the renderer does not come up
        self.camera = camera
        key = self.keys.camera_frame(self.p.camera.name)
        self._camera_stop = threading.Event()
        self._camera_thread = threading.Thread(target=self.camera.serve, name="sim-camera-publisher",
                                               args=(lambda f: self.node.publish(key, f), self._camera_stop),
                                               daemon=True)
        self._camera_thread.start()

    def close(self) -> None:
        if self._camera_thread is not None:
            self._camera_stop.set()
            self._camera_thread.join(5.0)
            self._camera_thread = None
        if self.camera is not None:
            self.camera.close()
            self.camera = None
        self.core.close()

    # -- loops -------------------------------------------------------------------------------------
    def _run_lockstep(self) -> None:
        inbox = self.node.inbox(self._commands_key, TorqueCommand)
        self._bad_sources = [inbox]
        self._publish_state()
        last_pub = time.monotonic()
        republish = self.p.lockstep_republish_s
        t_prev = time.perf_counter_ns()
        while not self.stop.is_set():
            t0 = time.perf_counter_ns()
            cmd = inbox.get(min(republish, 0.05))
            now = time.monotonic()
            self._publish_status()
            if now - last_pub >= republish:  # on every pass: stale-seq chatter must not starve a late peer
                self._publish_state()
                self.counters["states_republished"] += 1
                last_pub = now
            if cmd is None:
                continue
            if cmd.seq != self.core.steps:
                self.counters["commands_out_of_sequence"] += 1
                continue
            command = self.gate.accept(cmd)
            if command is None:
                continue
            t1 = time.perf_counter_ns()
            self.core.step(command)
            self.braked = self.core.robot.braked
            self._after_step(wait_for_camera=self.p.lockstep_camera_sync)
            t2 = time.perf_counter_ns()
            self._publish_state()
            last_pub = now
            t3 = time.perf_counter_ns()
            self.timing.add((t3 - t_prev) / 1e3, (t1 - t0) / 1e3, (t2 - t1) / 1e3, (t3 - t2) / 1e3)
            t_prev = t3
            if self.p.max_steps and self.core.steps >= self.p.max_steps:
                break

    def _run_realtime(self) -> None:
        latest = self.node.latest(self._commands_key, TorqueCommand)
        self._bad_sources = [latest]
        period_ns = int(round(1e9 / self.p.rate_hz))
        stale_ns = int(self.p.stale_limit_s * 1e9)
        held: np.ndarray | str | None = None
        last_cmd_ns = -stale_ns - 1
        next_ns = time.monotonic_ns()
        t_prev = next_ns
        self._publish_state()
        while not self.stop.is_set():
            t0 = time.monotonic_ns()
            cmd = latest.take()
            if cmd is not None:
                accepted = self.gate.accept(cmd)
                if accepted is not None:
                    held = accepted if isinstance(accepted, str) else accepted.copy()
                    last_cmd_ns = t0
            fresh = held is not None and t0 - last_cmd_ns <= stale_ns
            if not fresh and held is not None and not self.braked:
                self.counters["stale_command_brakes"] += 1
                log.warning("no fresh command for %.0f ms: braking", (t0 - last_cmd_ns) / 1e6)
            t1 = time.monotonic_ns()
            self.core.step(held if fresh else HOLD)
            self.braked = self.core.robot.braked
            self._after_step(wait_for_camera=False)
            t2 = time.monotonic_ns()
            self._publish_state()
            self._publish_status()
            t3 = time.monotonic_ns()
            self.timing.add((t0 - t_prev) / 1e3, (t1 - t0) / 1e3, (t2 - t1) / 1e3, (t3 - t2) / 1e3)
            t_prev = t0
            if self.p.max_steps and self.core.steps >= self.p.max_steps:
                break
            next_ns += period_ns
            now = time.monotonic_ns()
            if now > next_ns:
                missed = (now - next_ns) // period_ns + 1
                self.timing.overruns += int(missed)
                next_ns += int(missed) * period_ns
            time.sleep((next_ns - now) / 1e9)

    # -- outputs -----------------------------------------------------------------------------------
    def _after_step(self, wait_for_camera: bool) -> None:
        k = self.core.steps
        if k % self._truth_every == 0:
            self._publish_truth()
        if self.camera is not None and k % self._camera_every == 0:
            if self.camera.dead:
                log.error("camera renderer process ended; the sim goes on without frames")
                self.counters["camera_renderer_died"] += 1
                self.camera.close()
                self.camera = None
                return
            if wait_for_camera and not self.camera.wait_idle(10.0):
                self.counters["camera_timeouts"] += 1
            self.camera.request(k, time.monotonic_ns(), self.core.time_ns, self.core.out.q,
                                self.core.dirt.dirt, self.core.dirt.version)

    def _publish_state(self) -> None:
        o = self.core.out
        self.node.publish(self.keys.robot_state, RobotState(
            seq=self.core.steps, stamp_ns=time.monotonic_ns(), q_rad=o.q.tolist(), dq_rad_s=o.dq.tolist(),
            tau_nm=o.tau.tolist(), wrench_world=o.wrench.tolist(), capabilities=self.caps,
            robot_time_ns=self.core.time_ns, wall_ns=time.time_ns()))

    def _publish_truth(self) -> None:
        d = self.core.dirt
        self.node.publish(self.keys.sim_truth, SimTruth(
            seq=self.core.steps, stamp_ns=time.monotonic_ns(), stain_ids=d.stain_ids,
            remaining=[float(v) for v in d.remaining()], total_dirt=d.total(),
            contact_force_n=float(self.core.out.normal_force_n), robot_time_ns=self.core.time_ns,
            centres_board_m=self._centres, sizes_m=self._sizes, T_board_to_world=self._board_pose))

    def status(self) -> ServiceStatus:
        counters = dict(self.counters)
        for source in getattr(self, "_bad_sources", []):
            counters["commands_received"] = counters.get("commands_received", 0) + source.received
            for reason, n in source.bad.items():
                counters[f"commands_dropped_bad_payload: {reason}"] = n
        if self.core.out.arm_contact:
            counters["arm_touching_board"] = 1
        if self.camera is not None:
            counters.update(camera_frames=self.camera.rendered, camera_ticks_skipped=self.camera.skipped)
        detail = f"mode={self.p.mode} step={self.core.steps} braked={self.braked}"
        return ServiceStatus(service=SERVICE, seq=self.core.steps, stamp_ns=time.monotonic_ns(),
                             counters=counters, detail=detail, timing=self.timing.summary())

    def _publish_status(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._next_status:
            return
        self._next_status = now + self._status_period_s
        self.node.publish(self.keys.sim_status, self.status())
