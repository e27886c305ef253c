"""Where frames come from: Zenoh camera messages, an image folder, a video file or a capture device.

Every source turns its input into a :class:`~perception.frames.Frame` and
counts what it could not use by reason, so the rest of perception is one
code path. ``read()`` never raises on bad input; it returns None when there
is no (usable) frame now, and sets ``ended`` when a finite source is done.
Sources without a camera model of their own (files, devices) take it from
``[perception.camera_model]``.
"""

from __future__ import annotations

import functools
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

from interfaces.messages import CameraFrame

from .calibration import Calibration, CalibrationError, Undistorter, read_calibration
from .frames import Frame, FrameError, frame_from_message
from .live_capture import LiveCapture, open_device
from .params import CameraModelParams, PerceptionParams, parse_source

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: The default focal length of a D435i colour stream at 640 px width [px].
DEFAULT_FX_AT_640 = 615.0


def camera_model(params: CameraModelParams, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """``(K (3, 3), T_camera_to_world (4, 4))`` of a configured camera for frames of ``width`` x ``height``
    (with a calibration file: its K scaled to the frames; the frames must be undistorted, :func:`undistorter`)."""
    if params.calibration:
        K = _calibration(params.calibration).at(width, height).K
    else:
        f = DEFAULT_FX_AT_640 * width / 640.0
        K = np.array([[params.fx or f, 0.0, params.cx or (width - 1) / 2.0],
                      [0.0, params.fy or f, params.cy or (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    position, target, up = (np.array(v, float) for v in (params.position_m, params.look_at_m, params.up_m))
    z = target - position
    z /= np.linalg.norm(z)
    y = -(up - (up @ z) * z)
    if np.linalg.norm(y) < 1e-6:
        raise FrameError("bad camera model: up_m is parallel to the viewing direction")
    y /= np.linalg.norm(y)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
    T[:3, 3] = position
    return K, T


@functools.lru_cache(maxsize=8)
def _calibration(path: str) -> Calibration:
    return read_calibration(path)


@functools.lru_cache(maxsize=8)
def undistorter(path: str, width: int, height: int) -> Undistorter:
    """The undistortion of the calibration in ``path`` for frames of ``width`` x ``height`` (made once)."""
    return Undistorter(_calibration(path).at(width, height))


class ZenohSource:
    """Newest camera frame on ``camera/<name>/frame`` (older ones are superseded, counted as dropped)."""

    ended = False

    def __init__(self, node, camera: str) -> None:
        self.reader = node.latest(node.keys.camera_frame(camera), CameraFrame)
        self.counters: Counter[str] = Counter()
        self._last_seq: int | None = None

    def read(self) -> Frame | None:
        msg = self.reader.take()
        for reason, n in self.reader.bad.items():  # undecodable payloads, counted by the reader
            self.counters[f"frames_bad: {reason}"] = n
        if msg is None:
            return None
        if self._last_seq is not None and msg.seq > self._last_seq + 1:
            self.counters["frames_dropped"] += msg.seq - self._last_seq - 1
        self._last_seq = msg.seq
        try:
            return frame_from_message(msg)
        except FrameError as exc:
            self.counters[f"frames_bad: {str(exc).split(':')[0]}"] += 1
            return None

    def close(self) -> None:
        self.reader.close()


class OpenCVSource:
    """Frames from an image folder (sorted by name), a video file or a capture device (e.g. a UVC RealSense).

    Folder frames are stamped ``index / rate_hz`` and video frames by their
    position in the file, so debounce times mean the same as live; device
    frames by the monotonic clock at their arrival, read on a thread of
    their own that keeps only the newest (:mod:`perception.live_capture`:
    the device asked for ``device_size_px`` at ``device_fps`` in
    ``device_fourcc``).
    """

    def __init__(self, spec: str, params: PerceptionParams) -> None:
        self.kind, arg = parse_source(spec)
        self.model = params.model
        if self.model.calibration:
            _calibration(self.model.calibration)  # an unusable file is refused now, naming it
        self.rate_hz = params.source_rate_hz
        self.counters: Counter[str] = Counter()
        self.ended = False
        self._seq = 0
        self._files: list[Path] = []
        self._cap = None
        self._live: LiveCapture | None = None
        if self.kind == "folder":
            folder = Path(arg)
            if not folder.is_dir():
                raise FileNotFoundError(f"image folder {arg!r} does not exist")
            self._files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            if not self._files:
                raise FileNotFoundError(f"image folder {arg!r} has no {'/'.join(IMAGE_SUFFIXES)} files")
        elif self.kind == "video":
            self._cap = cv2.VideoCapture(arg)
            if not self._cap.isOpened():
                raise FileNotFoundError(f"cannot open video {arg!r}")
        elif self.kind == "device":
            self._live = LiveCapture(open_device(arg, params.device_size_px, params.device_fps, params.device_fourcc))
            self.counters = self._live.counters
        else:
            raise ValueError(f"OpenCVSource cannot read {spec!r}")

    def read(self) -> Frame | None:
        if self._live is not None:
            return self._read_live(self._live)
        if self.ended:
            return None
        t = self._seq / self.rate_hz
        if self.kind == "folder":
            if self._seq >= len(self._files):
                self.ended = True
                return None
            path = self._files[self._seq]
            bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
            self._seq += 1
            if bgr is None:
                self.counters["frames_bad: corrupt image file"] += 1
                return None
        else:
            cap = self._cap
            assert cap is not None  # a video file, opened with the source
            ok, bgr = cap.read()
            if not ok:
                self.ended = True
                return None
            self._seq += 1
            t = cap.get(cv2.CAP_PROP_POS_MSEC) / 1e3
        return self._frame(bgr, t, time.monotonic_ns())

    def _read_live(self, live: LiveCapture) -> Frame | None:
        self.ended = live.ended
        got = live.newest()
        if got is None:
            return None
        bgr, arrived_ns, wall_ns = got
        self._seq += 1
        return self._frame(bgr, arrived_ns * 1e-9, arrived_ns, wall_ns)

    def _frame(self, bgr: np.ndarray, t_s: float, stamp_ns: int, wall_ns: int = 0) -> Frame | None:
        """The frame of a BGR image shown at ``t_s`` [s], with the camera model (and undistortion) configured."""
        h, w = bgr.shape[:2]
        try:
            K, T = camera_model(self.model, w, h)
            if self.model.calibration:
                bgr = undistorter(self.model.calibration, w, h)(bgr)
        except (FrameError, CalibrationError) as exc:
            self.counters[f"frames_bad: {str(exc).split(':')[0]}"] += 1
            return None
        return Frame(np.ascontiguousarray(bgr[..., ::-1]), K, T, float(t_s), self._seq - 1, stamp_ns, wall_ns=wall_ns)

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
        if self._live is not None:
            self._live.close()
