"""The camera renders in its own process, on a mirrored scene, so the 1 kHz physics never waits for it.

The sim process owns a :class:`CameraProcess`. When the renderer is idle,
:meth:`CameraProcess.request` copies the dirt grid into shared memory and
sends the joint positions of the state to show; the renderer process
(``_render_main``, its own PyBullet client with the same robot and board)
poses the arm, renders (``[sim.camera] renderer``: the analytic camera of
:mod:`sim.analytic_camera`, or PyBullet's TinyRenderer), draws the dirt where the board is
visible (:class:`~sim.camera.DirtCompositor`) and writes the RGB image into a
second shared-memory buffer. A thread of the sim process (:class:`FramePublisher`) waits for the
renderer's answer, wraps the image in a :class:`~interfaces.messages.CameraFrame`
and publishes it, so neither rendering nor a megabyte-sized put sits in
the physics loop.

A process that runs cell after cell (a campaign's worker) can keep a run's
renderer for the next run with the same scene (:func:`keep_renderers`,
:func:`open_camera`, :func:`release_camera`): a frame depends only on the
joint positions and the dirt of its request, so a kept renderer draws the
same frames as a new one, without a new interpreter and scene per run.
"""

from __future__ import annotations

import atexit
import logging
import multiprocessing as mp
import os
import pickle
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing import shared_memory

import cv2
import numpy as np

from interfaces.messages import CameraFrame
from interfaces.transforms import pose_from_transform
from lampskit.errors import LampsError
from runtime.priority import BACKGROUND, set_service_priority

from .board import Board
from .camera import (
    DirtCompositor,
    board_cell_index,
    board_texture,
    camera_pose,
    intrinsics_of,
    light_towards,
    marker_layer,
    projection_matrix,
    view_matrix,
)
from .params import SimParams

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class _Setup:
    params: SimParams
    board: Board
    q_start: np.ndarray
    dirt_shape: tuple[int, int]
    cell_m: float
    dirt_shm: str
    image_shm: str


def _render_main(conn, setup: _Setup) -> None:  # runs in the renderer process
    import signal

    import pybullet as pb

    from .world import build_world

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the sim, which then stops us in order
    try:  # the renderer is background work: the 1 kHz loops go first (runtime.priority)
        set_service_priority(BACKGROUND)
    except LampsError as exc:
        log.warning("camera renderer priority: %s", exc)
    cam = setup.params.camera
    dirt_shm = shared_memory.SharedMemory(setup.dirt_shm)
    image_shm = shared_memory.SharedMemory(setup.image_shm)
    try:
        dirt = np.ndarray(setup.dirt_shape, np.float32, dirt_shm.buf)
        image = np.ndarray((cam.height, cam.width, 3), np.uint8, image_shm.buf)
        client = pb.connect(pb.DIRECT)
        world = build_world(client, setup.board, setup.params.contact, setup.q_start, visual=True)
        markers = marker_layer(setup.board.size_m)
        texture = board_texture(np.zeros_like(dirt), setup.cell_m, markers, setup.board.size_m)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "board.png")
            cv2.imwrite(path, texture[..., ::-1])
            tex_id = pb.loadTexture(path, physicsClientId=client)
        pb.changeVisualShape(world.board, -1, textureUniqueId=tex_id, physicsClientId=client)
        T_camera = camera_pose(cam, setup.board)
        view = view_matrix(T_camera)
        proj = projection_matrix(intrinsics_of(cam))
        light = light_towards(cam, setup.board)
        composite_dirt = DirtCompositor(board_cell_index(intrinsics_of(cam), T_camera, setup.board, setup.cell_m,
                                                         setup.dirt_shape))
        analytic = None
        if cam.renderer == "analytic":
            from .analytic_camera import AnalyticCamera

            analytic = AnalyticCamera(world, cam, intrinsics_of(cam), T_camera, np.asarray(light),
                                      setup.board.origin_m, setup.board.normal_world)
        conn.send(("ready", 0.0))
        while True:
            request = conn.recv()
            if request is None:
                break
            q, _dirt_version = request
            t0 = time.perf_counter()
            if analytic is not None:
                visible = analytic.render(image, q)
            else:
                for j, qj in zip(world.joints, q):
                    pb.resetJointState(world.robot, j, float(qj), physicsClientId=client)
                out = pb.getCameraImage(cam.width, cam.height, view, proj, renderer=pb.ER_TINY_RENDERER,
                                        shadow=int(cam.shadow), lightDirection=light,
                                        physicsClientId=client)
                image[...] = np.asarray(out[2], np.uint8).reshape(cam.height, cam.width, 4)[..., :3]
                visible = np.asarray(out[4]).reshape(-1) == world.board
            composite_dirt(image, visible, dirt)
            conn.send(("frame", time.perf_counter() - t0))
    except (EOFError, KeyboardInterrupt, BrokenPipeError):
        pass
    finally:
        dirt_shm.close()
        image_shm.close()


class CameraProcess:
    """The renderer process and its shared buffers; the sim's side of the camera.

    Attributes
    ----------
    requested, rendered, skipped : int
        Frames asked for, delivered, and camera ticks skipped because the
        renderer was still busy (real-time mode).
    render_s : list of float
        Render durations [s] of the last frames (for benchmarks).
    """

    def __init__(self, params: SimParams, board: Board, q_start: np.ndarray, dirt_shape: tuple[int, int]) -> None:
        cam = params.camera
        self.params = params
        self.intrinsics = intrinsics_of(cam)
        self.T_camera_to_world = camera_pose(cam, board)
        self._pose = pose_from_transform(self.T_camera_to_world)
        self._dirt_shm = shared_memory.SharedMemory(create=True, size=int(np.prod(dirt_shape)) * 4)
        self._image_shm = shared_memory.SharedMemory(create=True, size=cam.width * cam.height * 3)
        self.dirt = np.ndarray(dirt_shape, np.float32, self._dirt_shm.buf)
        self.image = np.ndarray((cam.height, cam.width, 3), np.uint8, self._image_shm.buf)
        setup = _Setup(params, board, np.asarray(q_start, float), dirt_shape, params.dirt.cell_m,
                       self._dirt_shm.name, self._image_shm.name)
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_render_main, args=(child, setup), name="lamps-sim-renderer", daemon=True)
        self._idle = threading.Event()
        self._closed = False
        self.dead = False
        self.scene_key = scene_key(params, board, q_start, dirt_shape)
        self._reset()

    def _reset(self) -> None:
        """No frame asked for or delivered yet (a new run)."""
        self._pending: tuple[int, int, int] | None = None
        self.requested = self.rendered = self.skipped = 0
        self.render_s: list[float] = []

    def start(self, timeout_s: float = 60.0) -> None:
        """Start the renderer and wait until its scene is built."""
        self._proc.start()
        try:
            if not self._conn.poll(timeout_s):
                raise RuntimeError(f"camera renderer did not start within {timeout_s} s")
            self._conn.recv()
        except (EOFError, OSError) as exc:
            self.close()
            raise RuntimeError(
                f"camera renderer failed while building its scene (exit code {self._proc.exitcode})") from exc
        except RuntimeError:
            self.close()
            raise
        self._idle.set()

    @property
    def idle(self) -> bool:
        return self._idle.is_set()

    def wait_idle(self, timeout_s: float) -> bool:
        return self._idle.wait(timeout_s)

    def request(self, seq: int, stamp_ns: int, robot_time_ns: int, q: np.ndarray,
                dirt: np.ndarray, dirt_version: int) -> bool:
        """Ask for a frame of state ``seq``; False (and counted) if the renderer is still busy."""
        if self.dead:
            return False
        if not self._idle.is_set():
            self.skipped += 1
            return False
        self._idle.clear()
        self.dirt[...] = dirt
        self._pending = (seq, stamp_ns, robot_time_ns)
        try:
            self._conn.send((np.asarray(q, float), dirt_version))
        except (OSError, ValueError):
            self._mark_dead()
            return False
        self.requested += 1
        return True

    def _mark_dead(self) -> None:
        self.dead = True
        self._idle.set()  # nobody may wait for a frame that will never come

    def serve(self, publish: Callable[[CameraFrame], None], stop: threading.Event) -> None:
        """Publish frames as the renderer finishes them until ``stop`` is set (run in a thread)."""
        while not stop.is_set():
            frame = self.take(0.05, stop)
            if frame is not None:
                publish(frame)
            elif self.dead:
                return

    def take(self, timeout_s: float, stop: threading.Event | None = None) -> CameraFrame | None:
        """The frame asked for last, once the renderer has finished it (waiting up to ``timeout_s``); None
        meanwhile, or when the renderer is gone (then :attr:`dead`, unless ``stop`` was set)."""
        try:
            if not self._conn.poll(timeout_s):
                return None
            _, render_s = self._conn.recv()
        except (EOFError, OSError):
            if stop is None or not stop.is_set():
                self._mark_dead()
            return None
        assert self._pending is not None  # set by the request this answers
        _state_seq, stamp_ns, robot_time_ns = self._pending
        data = self.image.tobytes()
        self._idle.set()
        self.render_s.append(render_s)
        del self.render_s[:-1000]
        self.rendered += 1
        cam = self.params.camera
        return CameraFrame(seq=self.rendered, stamp_ns=stamp_ns, camera=cam.name, encoding="rgb8", data=data,
                           intrinsics=self.intrinsics, T_camera_to_world=self._pose, robot_time_ns=robot_time_ns)

    def close(self) -> None:
        """Stop the renderer and free the shared memory (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._mark_dead()
        try:
            if self._proc.is_alive():
                self._conn.send(None)
                self._proc.join(5.0)
            if self._proc.is_alive():
                self._proc.terminate()
                self._proc.join(2.0)
        except (OSError, ValueError, AssertionError):
            pass
        self._conn.close()
        for shm in (self._dirt_shm, self._image_shm):
            shm.close()
            shm.unlink()


#: Renderers kept idle for the next run of this process (:func:`keep_renderers`): scene key -> renderer.
KEPT: dict[bytes, CameraProcess] = {}
#: At most this many kept at once (one per board and camera a campaign's worker meets; the oldest goes).
MAX_KEPT = 2
_keeping = False


def scene_key(params: SimParams, board: Board, q_start: np.ndarray, dirt_shape: tuple[int, int]) -> bytes:
    """What a renderer's scene is built from: the camera, the contact model of the world, the board, the arm's
    start and the dirt grid (not the stains, the seed or the physics rate: a frame draws them from its request)."""
    return pickle.dumps((params.camera, params.contact, params.dirt.cell_m, np.asarray(board.T_board_to_world, float),
                         np.asarray(board.size_m, float), float(board.thickness_m), np.asarray(q_start, float),
                         tuple(dirt_shape)))


def keep_renderers(on: bool = True) -> None:
    """Keep each run's renderer, once released, for the next run of this process with the same scene key; the kept
    ones are closed when the process exits."""
    global _keeping
    if on and not _keeping:
        atexit.register(_close_kept)
    _keeping = on
    if not on:
        _close_kept()


def _close_kept() -> None:
    while KEPT:
        KEPT.pop(next(iter(KEPT))).close()


def open_camera(params: SimParams, board: Board, q_start: np.ndarray, dirt_shape: tuple[int, int]) -> CameraProcess:
    """A started renderer for this scene: a kept one (counters back to zero) or a new one (RuntimeError if it does
    not come up)."""
    kept = KEPT.pop(scene_key(params, board, q_start, dirt_shape), None)
    if kept is not None and not kept.dead and kept._proc.is_alive():
        kept._reset()
        return kept
    if kept is not None:
        kept.close()
    camera = CameraProcess(params, board, q_start, dirt_shape)
    camera.start()  # closes itself and raises RuntimeError if the renderer does not come up
    return camera


def release_camera(camera: CameraProcess) -> None:
    """The run is done with ``camera``: kept for the next run (when keeping, and it is alive with no frame in
    flight, waiting up to 10 s for one asked for), else closed."""
    if _keeping and not camera.dead and not camera.idle:
        camera.take(10.0)  # the frame asked for last, never taken: the renderer is done with it first
    if not _keeping or camera.dead or not camera.idle or not camera._proc.is_alive():
        camera.close()
        return
    old = KEPT.pop(camera.scene_key, None)
    if old is not None and old is not camera:
        old.close()
    KEPT[camera.scene_key] = camera
    while len(KEPT) > MAX_KEPT:
        KEPT.pop(next(iter(KEPT))).close()
