"""``lamps perception`` as a Zenoh service: frames in, ``perception/stains`` out at a steady rate.

The loop takes the newest frame of its source (older frames are superseded
and counted), runs :class:`~perception.pipeline.Perception` on it and
publishes the stains; between frames it re-publishes the last stains so
the controller hears at least ``publish_rate_hz``. Without any frame for
``frame_timeout_s`` (wall clock) the stains go out as ``board = "lost"``:
unknown, never clean. A status (``ServiceStatus`` on ``perception/status``)
carries the counters (frames processed, dropped, bad by reason, board
held/lost) and the per-frame processing time; debug images (the rectified
board with occlusion and stains drawn, JPEG) go to ``perception/debug`` when
enabled. With ``tool_mask`` the service also follows ``robot/state``: the
robot's tool at each frame's time is masked out of the image
(:mod:`~perception.self_filter`), so its colour is never taken for ink.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec
import numpy as np

from interfaces.messages import CameraFrame, CameraIntrinsics, LoopTiming, RobotState, ServiceStatus, Stains
from interfaces.transforms import pose_from_transform

from .debug import debug_jpeg
from .params import PerceptionParams
from .pipeline import Perception, Result
from .self_filter import ToolTrack

if TYPE_CHECKING:
    from runtime.session import Latest

log = logging.getLogger(__name__)
SERVICE = "perception"
#: Idle wait of the loop when no frame is there [s].
IDLE_S = 0.002
#: A frame stamp older than this (or in the future) is not on this host's monotonic clock: no latency from it [ns].
LATENCY_SANE_NS = 10_000_000_000


class PerceptionService:
    """The loop around one :class:`Perception`; ``source`` has ``read() -> Frame | None``, ``ended``, ``counters``."""

    def __init__(self, params: PerceptionParams, node, source, sink=None, debug_dir=None) -> None:
        self.p = params
        self.node = node
        self.keys = node.keys if node is not None else None
        self.source = source
        self.sink = sink  # optional callable(Stains) for offline runs (JSON lines)
        #: with debug_images: every frame's debug image is also written here as frame-<seq>.jpg (offline checks)
        self.debug_dir = debug_dir
        self.perception = Perception(params)
        # the robot's joint states, to mask its tool out of the image (perception.self_filter)
        self.tool: ToolTrack | None = None
        self._robot_states: Latest[RobotState] | None = None
        if node is not None and params.tool_mask:
            self.tool = ToolTrack(params.tool_max_age_s)
            # the newest 512 states (0.5 s at 1 kHz) held by Zenoh, decoded only at each frame: no Python per state
            self._robot_states = node.latest(node.keys.robot_state, RobotState, depth=512)
        self.stop = threading.Event()
        self.counters: Counter[str] = Counter()
        self.last: Stains | None = None
        self.detail = "waiting for frames"
        self._process_us: deque[float] = deque(maxlen=500)  # wall clock per frame: waits for a core included
        self._process_cpu_us: deque[float] = deque(maxlen=500)  # the thread's CPU time per frame
        self._interval_us: deque[float] = deque(maxlen=500)
        self._latency_us: deque[float] = deque(maxlen=500)  # frame's stamp to its stains message, this host's clock
        self._capture_us: deque[float] = deque(maxlen=500)  # the camera's wall-clock stamp to the stains message
        self._last_frame_wall: float | None = None
        self._last_publish = -float("inf")
        self._next_status = 0.0
        self._next_debug = 0.0
        self._status_seq = 0

    def run(self) -> int:
        """Serve until stopped (or a finite source ends); returns the number of frames processed."""
        while not self.stop.is_set():
            frame = self.source.read()
            if frame is None and self.source.ended:
                break
            self.serve_once(frame, time.monotonic())
            if frame is None:
                self.stop.wait(IDLE_S)
        self._publish_status(time.monotonic(), force=True)
        return self.counters["frames_processed"]

    def serve_once(self, frame, now: float) -> None:
        """One pass of the loop at ``now`` [s, the loop's clock]: ``frame`` (or None) processed, the stains
        re-published when due, the status when due."""
        if frame is not None:
            self._handle(frame, now)
        self._keep_publishing(now)
        self._publish_status(now)

    def _tool_at(self, frame, now: float) -> np.ndarray | None:
        """The tool box (8, 3) [m] at the frame's time from the joint states received so far, or None."""
        if self.tool is None or self._robot_states is None:
            return None
        for state in self._robot_states.take_all():
            self.tool.add(state.robot_time_ns, state.q_rad, now, state.dq_rad_s)
        return self.tool.corners_at(frame.robot_time_ns, now)

    def _arm_at(self, frame, now: float):
        """With ``arm_mask``: the joint state for the frame (:meth:`ToolTrack.arm_at`), or None."""
        if self.tool is None or not self.p.arm_mask:
            return None
        return self.tool.arm_at(frame.robot_time_ns, now)

    def _handle(self, frame, now: float) -> None:
        t0, cpu0 = time.perf_counter(), time.thread_time_ns()
        try:
            result = self.perception.process(frame, self._tool_at(frame, now), self._arm_at(frame, now))
        except Exception as exc:  # never the loop's end: count, log, go on with the next frame
            self.counters[f"frames_failed: {type(exc).__name__}"] += 1
            log.exception("processing frame %d failed", frame.seq)
            return
        self._process_us.append((time.perf_counter() - t0) * 1e6)
        self._process_cpu_us.append((time.thread_time_ns() - cpu0) * 1e-3)
        if self._last_frame_wall is not None:
            self._interval_us.append((now - self._last_frame_wall) * 1e6)
        self._last_frame_wall = now
        self.counters["frames_processed"] += 1
        if result.reason:
            self.counters[f"frames_not_fresh: {result.reason.split(':')[0].split(';')[0][:50]}"] += 1
        self.detail = self._describe(result)
        if result.stains is not None:
            self._publish(result.stains, now)
            age_ns = time.monotonic_ns() - frame.stamp_ns
            if frame.stamp_ns > 0 and 0 <= age_ns < LATENCY_SANE_NS:  # a stamp of this host's monotonic clock
                self._latency_us.append(age_ns * 1e-3)
            age_ns = time.time_ns() - frame.wall_ns
            if frame.wall_ns > 0 and 0 <= age_ns < LATENCY_SANE_NS:  # the camera's clock is this host's (or PTP's)
                self._capture_us.append(age_ns * 1e-3)
        if self.p.debug_images and result.rect is not None and self.debug_dir is not None:
            self._write_debug(result, frame)
        if self.p.debug_images and result.rect is not None and now >= self._next_debug and self.node is not None:
            self._next_debug = now + 1.0 / self.p.debug_rate_hz
            self._publish_debug(result, frame)

    def _describe(self, result: Result) -> str:
        if result.stains is None:
            return result.reason
        n = len(result.stains.stains)
        done = sum(s.kappa for s in result.stains.stains)
        text = f"board {result.stains.board}, {n} stains, {done} done"
        return f"{text} ({result.reason})" if result.reason else text

    def _publish(self, msg: Stains, now: float) -> None:
        self.last = msg
        self._last_publish = now
        self.counters[f"stains_published_{msg.board}"] += 1
        if self.node is not None:
            self.node.publish(self.node.keys.perception_stains, msg)
        if self.sink is not None:
            self.sink(msg)

    def _keep_publishing(self, now: float) -> None:
        """Re-publish between frames; without frames for ``frame_timeout_s`` the stains are unknown."""
        if self.last is None or now - self._last_publish < 1.0 / self.p.publish_rate_hz:
            return
        msg = self.last
        if self._last_frame_wall is not None and now - self._last_frame_wall > self.p.frame_timeout_s \
                and msg.board != "lost":
            msg = msgspec.structs.replace(msg, board="lost", stains=[
                msgspec.structs.replace(s, visible=0.0, kappa=False) for s in msg.stains])
            self.detail = f"no camera frame for {now - self._last_frame_wall:.1f} s: stains unknown"
            self.counters["camera_silent"] += 1
        self._publish(msgspec.structs.replace(msg, stamp_ns=time.monotonic_ns()), now)

    def _write_debug(self, result: Result, frame) -> None:
        """The frame's debug image (the rectified board, stains drawn) as ``<debug_dir>/frame-<seq>.jpg``."""
        from lampskit.atomic import write_atomic

        data, _ = debug_jpeg(result, self.perception)
        write_atomic(Path(self.debug_dir) / f"frame-{frame.seq:06d}.jpg", lambda f: f.write(data))
        self.counters["debug_images_written"] += 1

    def _publish_debug(self, result: Result, frame) -> None:
        data, (h, w) = debug_jpeg(result, self.perception)
        res = self.p.board.resolution_m
        intr = CameraIntrinsics(1.0 / res, 1.0 / res, 0.0, 0.0, w, h)  # pixels per metre on the board
        assert result.board is not None  # a rectified image has its board
        self.node.publish(self.node.keys.perception_debug, CameraFrame(
            seq=frame.seq, stamp_ns=time.monotonic_ns(), camera="rectified-board", encoding="jpeg", data=data,
            intrinsics=intr, T_camera_to_world=pose_from_transform(result.board.T_board_to_world),
            robot_time_ns=frame.robot_time_ns))

    def status(self) -> ServiceStatus:
        counters = dict(self.counters)
        counters.update(self.source.counters)
        counters["board_resets"] = self.perception.resets
        counters["frames_marker_left_out"] = self.perception.board.markers_left_out
        if self.tool is not None:
            counters["frames_tool_masked"] = self.tool.used
            counters["frames_tool_pose_unknown"] = self.tool.unknown
            for reason, n in (self._robot_states.bad if self._robot_states is not None else {}).items():
                counters[f"robot_states_bad: {reason}"] = n
        proc = np.array(self._process_us) if self._process_us else np.zeros(1)
        gap = np.array(self._interval_us) if self._interval_us else np.zeros(1)
        timing = LoopTiming(period_p50_us=float(np.percentile(gap, 50)), period_p99_us=float(np.percentile(gap, 99)),
                            period_max_us=float(gap.max()), update_p99_us=float(np.percentile(proc, 99)),
                            ticks=self.counters["frames_processed"])
        counters["process_p50_us"] = int(np.percentile(proc, 50))
        if self._process_cpu_us:  # against the wall clock's: the share of a core the frames got
            counters["process_cpu_p50_us"] = int(np.percentile(self._process_cpu_us, 50))
        if self._latency_us:
            counters["frame_to_stains_p50_us"] = int(np.percentile(self._latency_us, 50))
            counters["frame_to_stains_p99_us"] = int(np.percentile(self._latency_us, 99))
        if self._capture_us:
            counters["capture_to_stains_p50_us"] = int(np.percentile(self._capture_us, 50))
            counters["capture_to_stains_p99_us"] = int(np.percentile(self._capture_us, 99))
        self._status_seq += 1
        return ServiceStatus(service=SERVICE, seq=self._status_seq, stamp_ns=time.monotonic_ns(), counters=counters,
                             detail=self.detail, timing=timing)

    def _publish_status(self, now: float, force: bool = False) -> None:
        if self.node is None or (not force and now < self._next_status):
            return
        self._next_status = now + 1.0 / self.p.status_rate_hz
        self.node.publish(self.node.keys.perception_status, self.status())
