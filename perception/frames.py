"""One frame type after decoding, whatever the source: a Zenoh :class:`~interfaces.messages.CameraFrame`,
an image file, a video frame or a capture device.

:func:`frame_from_message` decodes raw (``rgb8``/``bgr8``/``mono8``) and
compressed (``jpeg``/``png``) images; every way a frame can be unusable
raises :class:`FrameError` with a short reason (the service counts frames by
that reason and goes on).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from interfaces.messages import CameraFrame, CameraIntrinsics
from interfaces.transforms import transform_from_pose
from lampskit.errors import LampsError


class FrameError(LampsError, ValueError):
    """A frame that cannot be used; ``str(exc)`` starts with a short reason (``"corrupt jpeg: ..."``)."""


@dataclass(frozen=True)
class Frame:
    """A decoded camera image and what is needed to use it.

    rgb : array, shape (height, width, 3), uint8, RGB. K : (3, 3) camera
    matrix [px]. T_camera_to_world : (4, 4) optical frame (x right, y down,
    z forward) in the world (robot base) frame. t_s : the time shown [s]
    (the robot's clock for simulated frames, so debounce times mean the same
    in lock-step). seq : the source's frame counter. stamp_ns : the source's
    monotonic stamp; robot_time_ns : the robot's clock (0 when unknown);
    wall_ns : when the camera took it, on the wall clock [ns since the epoch]
    (a ROS header's stamp; 0 when unknown).
    """

    rgb: np.ndarray
    K: np.ndarray
    T_camera_to_world: np.ndarray
    t_s: float
    seq: int
    stamp_ns: int = 0
    robot_time_ns: int = 0
    wall_ns: int = 0


def camera_matrix(k: CameraIntrinsics) -> np.ndarray:
    """(3, 3) pinhole camera matrix of ``k``."""
    return np.array([[k.fx, 0.0, k.cx], [0.0, k.fy, k.cy], [0.0, 0.0, 1.0]])


def _decompress(data: bytes, encoding: str, width: int, height: int) -> np.ndarray:
    buf = np.frombuffer(data, np.uint8)
    bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR) if buf.size else None
    if bgr is None:
        raise FrameError(f"corrupt {encoding}: {len(data)} bytes do not decode")
    if bgr.shape[:2] != (height, width):
        raise FrameError(f"size mismatch: {encoding} image is {bgr.shape[1]}x{bgr.shape[0]}, "
                         f"intrinsics say {width}x{height}")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def rgb_from_message(msg: CameraFrame) -> np.ndarray:
    """(height, width, 3) uint8 RGB image of ``msg``; FrameError if it cannot be decoded."""
    k = msg.intrinsics
    w, h = k.width, k.height
    if msg.encoding in ("jpeg", "png"):
        return _decompress(msg.data, msg.encoding, w, h)
    channels = {"rgb8": 3, "bgr8": 3, "mono8": 1}.get(msg.encoding)
    if channels is None:
        raise FrameError(f"unknown encoding: {msg.encoding!r}")
    if len(msg.data) != w * h * channels:  # the message checks this too; frames built in code may not
        raise FrameError(f"truncated {msg.encoding}: {len(msg.data)} bytes for {w}x{h}")
    img = np.frombuffer(msg.data, np.uint8).reshape(h, w, channels)
    if msg.encoding == "bgr8":
        return img[..., ::-1]
    if msg.encoding == "mono8":
        return np.repeat(img, 3, axis=2)
    return img


def frame_from_message(msg: CameraFrame) -> Frame:
    """A :class:`Frame` of a camera message; its time is the robot's clock when given, else the stamp."""
    rgb = rgb_from_message(msg)
    T = transform_from_pose(msg.T_camera_to_world)
    if not np.all(np.isfinite(T)):
        raise FrameError("bad camera pose: not finite")
    t_ns = msg.robot_time_ns if msg.robot_time_ns > 0 else msg.stamp_ns
    return Frame(rgb, camera_matrix(msg.intrinsics), T, t_ns * 1e-9, msg.seq, msg.stamp_ns, msg.robot_time_ns)
