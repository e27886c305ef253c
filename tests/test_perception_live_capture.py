"""A live camera's frames, newest only (perception/live_capture.py), through OpenCV's real capture and decoding.

No camera is attached here: an MJPG video written by OpenCV stands in for the device's stream (the same
``VideoCapture.read`` and JPEG decoding a UVC camera's MJPG frames go through), paced at the camera's 30 frames/s;
each frame carries its number in its pixels, so the test sees which frame perception got.
"""

from __future__ import annotations

import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from interfaces.errors import ConfigError
from perception.live_capture import LiveCapture, open_device
from perception.params import PerceptionParams, parse_source

from .conftest import REPO

N_FRAMES = 60


@pytest.fixture(scope="module")
def mjpg_video(tmp_path_factory):
    path = tmp_path_factory.mktemp("camera") / "stream.avi"
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (320, 240))
    assert out.isOpened()
    for i in range(N_FRAMES):
        img = np.full((240, 320, 3), 40 + 3 * i, np.uint8)  # the frame's number in its brightness
        out.write(img)
    out.release()
    return path


class Paced:
    """A capture that sends its frames at ``fps``, as a camera does (reading never runs ahead of the clock)."""

    def __init__(self, cap: cv2.VideoCapture, fps: float) -> None:
        self.cap, self.period, self.next = cap, 1.0 / fps, time.monotonic()

    def read(self):
        self.next += self.period
        time.sleep(max(0.0, self.next - time.monotonic()))
        return self.cap.read()

    def release(self) -> None:
        self.cap.release()


def _number(bgr: np.ndarray) -> int:
    return int(round((float(bgr.mean()) - 40) / 3))


def test_a_slow_reader_gets_the_newest_frame_and_the_skipped_ones_are_counted(mjpg_video):
    live = LiveCapture(Paced(cv2.VideoCapture(str(mjpg_video)), 30.0), max_failures=3)
    try:
        taken = []
        deadline = time.monotonic() + 10.0
        while not live.ended and time.monotonic() < deadline:
            got = live.newest()
            if got is not None:
                bgr, arrived_ns, wall_ns = got
                assert 0 <= time.monotonic_ns() - arrived_ns < 1e9 and abs(time.time_ns() - wall_ns) < 1e9
                taken.append(_number(bgr))
            time.sleep(0.1)  # a perception three times slower than the camera
        assert live.ended, "the stream's end is seen"
    finally:
        live.close()
    # every frame taken is newer than the last, none twice, and each was the newest when taken: at 30/s and a
    # take every 0.1 s about three frames each, two of them superseded
    assert taken == sorted(set(taken)) and len(taken) >= 10, taken
    skipped = np.diff(taken)
    assert np.median(skipped) >= 2, taken
    assert live.counters["frames_superseded"] >= N_FRAMES - len(taken) - 3, live.counters


def test_a_reader_that_keeps_up_gets_every_frame(mjpg_video):
    live = LiveCapture(Paced(cv2.VideoCapture(str(mjpg_video)), 30.0), max_failures=3)
    try:
        taken = []
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            got = live.newest()
            if got is not None:
                taken.append(_number(got[0]))
            elif live.ended:
                break
            time.sleep(0.002)
    finally:
        live.close()
    # a loaded machine may starve the reader for a frame's time now and then: almost every frame, in order
    assert taken == sorted(set(taken)) and len(taken) >= N_FRAMES - 3, taken
    assert live.counters["frames_superseded"] == N_FRAMES - len(taken), live.counters


def test_a_missing_device_is_named_and_the_device_settings_are_checked():
    with pytest.raises(FileNotFoundError, match="cannot open capture device '/dev/video-none'"):
        open_device("/dev/video-none", (1280, 720), 30.0, "MJPG")
    assert parse_source("device:/dev/video2") == ("device", "/dev/video2")
    with pytest.raises(ConfigError, match="device:/dev/videoN"):
        parse_source("device:/etc/../x y")
    for bad, match in (({"device_size_px": [1280.5, 720]}, "device_size_px"), ({"device_fourcc": "MJPEG"},
                                                                                "device_fourcc"),
                       ({"device_fps": 0.0}, "device_fps")):
        with pytest.raises(ConfigError, match=match):
            PerceptionParams.from_table(bad)
    assert PerceptionParams().device_size_px == (1280, 720)
    r = subprocess.run([sys.executable, "-m", "perception.cli", "--source", "device:/dev/video-none", "--no-zenoh"],
                       cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "cannot open capture device '/dev/video-none'" in r.stderr, r.stderr
