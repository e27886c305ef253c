"""ROS 2 camera topics as perception frames: ``sensor_msgs/msg/Image``, ``CompressedImage`` and ``CameraInfo``.

A real camera's ROS driver (``realsense2_camera``, ``usb_cam``, ...) reaches
the cell through zenoh-bridge-ros2dds, which carries each ROS message as its
CDR bytes on the key of its topic name (``/camera/color/image_raw`` ->
``camera/color/image_raw``). The bytes are decoded with rosbags' typestore
(ROS 2 Humble's definitions), the same as the lbr stack's messages.

* :func:`decode_image`: ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8`` and ``mono8``
  (rows may be padded: ``step``); anything else is refused, naming it.
* :func:`decode_compressed`: JPEG or PNG (``format``), decoded by OpenCV.
* :func:`decode_camera_info`: ``k`` and ``d`` (``plumb_bob`` or
  ``rational_polynomial``) as a :class:`~perception.calibration.Calibration`.

:class:`RosImageSource` reads the newest image of a topic (``ros:TOPIC``; a
topic ending in ``/compressed`` is a ``CompressedImage``) and the camera's
``camera_info`` beside it (image_transport's convention: the image topic's
namespace + ``camera_info``): its intrinsics, and its lens distortion undone,
once one has arrived; until then ``[perception.camera_model]``'s.
"""

from __future__ import annotations

import time
from collections import Counter

import cv2
import numpy as np

from .calibration import Calibration, CalibrationError, Undistorter
from .frames import Frame, FrameError

_TYPES = {"image": "sensor_msgs/msg/Image", "compressed": "sensor_msgs/msg/CompressedImage",
          "info": "sensor_msgs/msg/CameraInfo"}
_CHANNELS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}
#: A larger payload is dropped before it is decoded (counted): 8K RGBA is 133 MB, a 4K RGB frame 25 MB.
MAX_IMAGE_BYTES = 64 * 1024 * 1024


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


_STORE = None


def store():
    """ROS 2 Humble's message definitions (rosbags), made once."""
    global _STORE
    if _STORE is None:
        _STORE = _typestore()
    return _STORE


def _deserialize(raw: bytes, kind: str):
    try:
        return store().deserialize_cdr(raw, _TYPES[kind])
    except Exception as exc:  # rosbags raises several types for truncated or foreign bytes
        raise FrameError(f"not a {_TYPES[kind]}: {type(exc).__name__}") from None


def stamp_ns(msg) -> int:
    """The header's stamp [ns]."""
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def decode_image(raw: bytes) -> tuple[np.ndarray, int]:
    """(rgb (H, W, 3) uint8, stamp [ns]) of a CDR ``sensor_msgs/msg/Image``; FrameError naming what is wrong."""
    msg = _deserialize(raw, "image")
    enc = str(msg.encoding).lower()
    if enc not in _CHANNELS:
        raise FrameError(f"image encoding {msg.encoding!r} is not read (rgb8, bgr8, rgba8, bgra8, mono8)")
    h, w, step, c = int(msg.height), int(msg.width), int(msg.step), _CHANNELS[enc]
    data = np.asarray(msg.data, np.uint8)
    if h <= 0 or w <= 0 or step < w * c or data.size < h * step:
        raise FrameError(f"image of {w} x {h} px, step {step}, has {data.size} bytes")
    img = data[:h * step].reshape(h, step)[:, :w * c].reshape(h, w, c)
    if enc == "mono8":
        rgb = np.repeat(img, 3, axis=2)
    elif enc.startswith("bgr"):
        rgb = img[..., 2::-1]
    else:
        rgb = img[..., :3]
    return np.ascontiguousarray(rgb), stamp_ns(msg)


def decode_compressed(raw: bytes) -> tuple[np.ndarray, int]:
    """(rgb (H, W, 3) uint8, stamp [ns]) of a CDR ``sensor_msgs/msg/CompressedImage`` (JPEG or PNG)."""
    msg = _deserialize(raw, "compressed")
    bgr = cv2.imdecode(np.asarray(msg.data, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FrameError(f"compressed image ({msg.format!r}) does not decode")
    return np.ascontiguousarray(bgr[..., ::-1]), stamp_ns(msg)


def decode_camera_info(raw: bytes) -> Calibration:
    """The intrinsics and distortion of a CDR ``sensor_msgs/msg/CameraInfo``; FrameError naming what is wrong."""
    msg = _deserialize(raw, "info")
    if str(msg.distortion_model) not in ("plumb_bob", "rational_polynomial", ""):
        raise FrameError(f"camera_info distortion_model {msg.distortion_model!r} is not read")
    K = np.asarray(msg.k, float).reshape(3, 3)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.all(np.isfinite(K)):
        raise FrameError("camera_info has no usable K (an uncalibrated camera)")
    return Calibration(K, np.asarray(msg.d, float), int(msg.width), int(msg.height))


def info_topic(image_topic: str) -> str:
    """The ``camera_info`` topic beside an image topic (``/camera/color/image_raw[/compressed]`` ->
    ``/camera/color/camera_info``)."""
    parts = image_topic.rstrip("/").split("/")
    if parts[-1] == "compressed":
        parts = parts[:-1]
    return "/".join(parts[:-1] + ["camera_info"])


def topic_key(topic: str) -> str:
    """The Zenoh key zenoh-bridge-ros2dds carries a ROS topic on (no namespace configured on the bridge)."""
    return topic.strip("/")


class RosImageSource:
    """The newest image of a ROS 2 topic through zenoh-bridge-ros2dds (see the module docstring)."""

    ended = False

    def __init__(self, node, topic: str, params) -> None:
        import zenoh

        from .sources import camera_model

        self.model = params.model
        self._camera_model = camera_model
        self.compressed = topic.rstrip("/").endswith("/compressed")
        self.topic = topic
        self.info_topic = info_topic(topic)
        self.counters: Counter[str] = Counter()
        self._images = node.session.declare_subscriber(topic_key(topic), zenoh.handlers.RingChannel(1))
        self._infos = node.session.declare_subscriber(topic_key(self.info_topic), zenoh.handlers.RingChannel(1))
        self.calibration: Calibration | None = None
        self._undistort: Undistorter | None = None
        self._seq = 0
        self._last_stamp: int | None = None

    def _take_info(self) -> None:
        sample = self._infos.try_recv()
        if sample is None or len(sample.payload) > 65536:  # a CameraInfo is a few hundred bytes
            return
        try:
            cal = decode_camera_info(sample.payload.to_bytes())
        except FrameError as exc:
            self.counters[f"camera_info_bad: {str(exc).split(':')[0][:50]}"] += 1
            return
        if self.calibration is None or not (np.array_equal(cal.K, self.calibration.K)
                                            and np.array_equal(cal.dist, self.calibration.dist)):
            self.calibration = cal
            self._undistort = None

    def read(self) -> Frame | None:
        """The newest image not yet read as a Frame, or None; never raises on bad data (counted)."""
        self._take_info()
        sample = self._images.try_recv()
        if sample is None:
            return None
        arrived_ns = time.monotonic_ns()  # before decoding: the frame's age counts the decoding too
        if len(sample.payload) > MAX_IMAGE_BYTES:
            self.counters["frames_bad: image over the size bound"] += 1
            return None
        try:
            rgb, stamp = (decode_compressed if self.compressed else decode_image)(sample.payload.to_bytes())
            h, w = rgb.shape[:2]
            if self.calibration is not None:
                cal = self.calibration.at(w, h)
                if self._undistort is None or self._undistort.calibration.width != w:
                    self._undistort = Undistorter(cal)
                rgb = self._undistort(rgb)
                K = cal.K
                _, T = self._camera_model(self.model, w, h)
            else:
                K, T = self._camera_model(self.model, w, h)
        except (FrameError, CalibrationError) as exc:
            self.counters[f"frames_bad: {str(exc).split(':')[0][:50]}"] += 1
            return None
        if self._last_stamp is not None and stamp == self._last_stamp:
            self.counters["frames_repeated"] += 1
        self._last_stamp = stamp
        self._seq += 1
        return Frame(rgb, K, T, stamp / 1e9 if stamp else time.monotonic(), self._seq - 1, arrived_ns,
                     wall_ns=stamp)

    def close(self) -> None:
        for sub in (self._images, self._infos):
            sub.undeclare()
