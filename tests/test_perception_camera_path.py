"""A real camera's path end to end: a ROS 2 image topic at 30 frames/s into a ``lamps perception`` process.

The bytes a camera's ROS driver sends through zenoh-bridge-ros2dds (``sensor_msgs/msg/Image`` rgb8 1280x720 as
rosbags serializes it, its header stamped by the wall clock, ``camera_info`` beside it) of a real photograph with
fresh sensor noise, put at the camera's rate over real Zenoh; perception with the real-board profile as its own
process. The rate itself is a benchmark's figure (bench/bench_camera_path.py, docs/perception.md#rate): here, that
the path works and says its latency.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from perception.ros_images import decode_image

from .conftest import REPO
from .test_perception_inks import LABELS

sys.path.insert(0, str(REPO / "bench"))
from bench_camera_path import noisy_frames, photograph, stamp, stream  # noqa: E402

pytestmark = pytest.mark.slow


def test_the_stamp_is_written_where_ros_reads_it():
    rgb, _ = photograph("straight")
    cdr = noisy_frames(rgb[:48, :64], 1)[0]
    decoded, stamp_ns = decode_image(bytes(stamp(cdr, 1_764_000_000_123_456_789)))
    assert stamp_ns == 1_764_000_000_123_456_789 and decoded.shape == (48, 64, 3)


def test_a_ros_camera_at_30_frames_a_second_gives_the_photographs_stains_and_their_latency(tmp_path):
    rgb, K = photograph("straight")
    r = stream(noisy_frames(rgb, 6), K, (1280, 720), seconds=4.0, rate_hz=30.0, log_dir=tmp_path)
    print({k: v for k, v in r.items()})
    assert r["sent"] >= 60 and not r["frames_bad"], r
    assert r["processed"] >= 10, r
    # every hand-labelled drawing found (a drawing may come as two stains in a noisy frame)
    assert r["board"] in ("seen", "held") and 6 <= len(r["stains"]) <= 8, r
    for label in LABELS["straight"]["stains"]:
        centre = np.mean(label["polygon_m"], axis=0)
        assert any(np.linalg.norm(centre - s["centre_board_m"]) <= 0.5 * s["size_m"] + 0.05 for s in r["stains"]), \
            (label["label"], r["stains"])
    # perception's own latency figures: from the frame's arrival, and from the camera's stamp (transport too)
    assert 0 < r["frame_to_stains_p50_ms"] <= r["frame_to_stains_p99_ms"], r
    assert r["frame_to_stains_p50_ms"] <= r["capture_to_stains_p50_ms"] < 10_000, r
    assert np.isfinite(r["processed_fps"])
