"""A live camera through OpenCV (V4L2 on Linux, a UVC webcam or a RealSense's colour node): the newest frame only.

A camera sends frames at its own rate whether perception keeps up or not.
Read in perception's loop, ``VideoCapture.read`` hands out the oldest frame
in the driver's queue (V4L2 keeps four by default): when a frame costs more
than the camera's period, every frame perception sees is older by the
queue's length (133 ms at 30 frames/s), and it stays so. :class:`LiveCapture`
reads on a thread of its own, as fast as the camera sends, and keeps only
the newest frame with its arrival stamps (this host's monotonic clock and
the wall clock); a frame not taken before the next one arrives is counted
superseded. :func:`open_device` asks the device for a size, rate and pixel
format (MJPG: a USB 2 UVC camera sends 1280x720 at 30 frames/s only
compressed) and says what it got.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from typing import Protocol

import cv2
import numpy as np

log = logging.getLogger(__name__)
#: A device that sends no frame for this long is reported (counted), each time [s].
SILENT_S = 1.0


class Capture(Protocol):
    """The part of ``cv2.VideoCapture`` a live capture uses."""

    def read(self) -> tuple[bool, np.ndarray | None]: ...

    def release(self) -> None: ...


def open_device(device: str, size_px: tuple[int, int], fps: float, fourcc: str) -> cv2.VideoCapture:
    """The capture device ``device`` (an index ``"0"`` or a path ``"/dev/video2"``) asked for ``size_px`` (width,
    height) [px] at ``fps`` [1/s] in pixel format ``fourcc`` ("" for the driver's own); raises FileNotFoundError
    naming the device when it cannot be opened. What the device granted is logged (it may differ)."""
    target = int(device) if device.isdigit() else device
    cap = cv2.VideoCapture(target, cv2.CAP_V4L2) if hasattr(cv2, "CAP_V4L2") else cv2.VideoCapture(target)
    if not cap.isOpened():
        cap = cv2.VideoCapture(target)  # another backend (not Linux, or a device V4L2 does not list)
    if not cap.isOpened():
        raise FileNotFoundError(f"cannot open capture device {device!r} (no such device, or in use)")
    if fourcc:
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*fourcc))
    cap.set(cv2.CAP_PROP_FRAME_WIDTH, size_px[0])
    cap.set(cv2.CAP_PROP_FRAME_HEIGHT, size_px[1])
    cap.set(cv2.CAP_PROP_FPS, fps)
    cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # honoured by V4L2; the thread keeps the newest frame either way
    got = (cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT), cap.get(cv2.CAP_PROP_FPS))
    log.info("capture device %s: asked %dx%d at %.0f/s, got %.0fx%.0f at %.0f/s", device, *size_px, fps, *got)
    return cap


class LiveCapture:
    """Reads ``cap`` on a thread; :meth:`newest` hands out each frame at most once, the newest one.

    Attributes
    ----------
    counters : Counter of str
        ``frames_superseded`` (a frame replaced before it was taken), ``frames_bad: capture failed`` (a read
        that returned nothing), ``camera_silent`` (no frame for :data:`SILENT_S`, once per silence).
    ended : bool
        ``max_failures`` reads in a row failed (a finite stream's end). A device is read with none: unplugged,
        it is silent (perception's stains turn "lost" after its ``frame_timeout_s``) until it is back.
    """

    def __init__(self, cap: Capture, max_failures: int | None = None) -> None:
        self.cap = cap
        self.counters: Counter[str] = Counter()
        self.ended = False
        self._max_failures = max_failures
        self._lock = threading.Lock()
        self._frame: tuple[np.ndarray, int, int] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-capture", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        failures, last = 0, time.monotonic()
        silent = False
        while not self._stop.is_set():
            ok, bgr = self.cap.read()
            now = time.monotonic()
            if not ok or bgr is None:
                failures += 1
                self.counters["frames_bad: capture failed"] += 1
                if not silent and now - last > SILENT_S:
                    silent = True
                    self.counters["camera_silent"] += 1
                if self._max_failures is not None and failures >= self._max_failures:
                    self.ended = True
                    return
                time.sleep(0.01)
                continue
            failures, last, silent = 0, now, False
            frame = (bgr, time.monotonic_ns(), time.time_ns())
            with self._lock:
                if self._frame is not None:
                    self.counters["frames_superseded"] += 1
                self._frame = frame

    def newest(self) -> tuple[np.ndarray, int, int] | None:
        """``(bgr (h, w, 3) uint8, arrival monotonic [ns], arrival wall clock [ns])`` of the newest frame not yet
        taken, or None."""
        with self._lock:
            frame, self._frame = self._frame, None
        return frame

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.cap.release()
