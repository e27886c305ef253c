"""ROS 2 camera topics as perception frames, bytes as rosbags writes them, over real Zenoh with the cell's identities.

Images and camera_info are serialized to CDR with rosbags (the bytes zenoh-bridge-ros2dds carries); a session with
the bridge's identity puts them on the topics' keys, perception (its own identity, the cell's access list) reads them
through ``--source ros:TOPIC``'s source.
"""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from perception.frames import FrameError
from perception.params import PerceptionParams
from perception.ros_images import RosImageSource, decode_camera_info, decode_compressed, decode_image, info_topic, store
from runtime.config import ZenohSettings
from runtime.credentials import identity_folder, make_credentials
from runtime.session import ServiceNode

from .conftest import REPO
from .zenoh_helpers import free_port, wait_for, wait_subscribed

PHOTO = REPO / "tests" / "fixtures" / "whiteboards" / "straight.jpg"


def _header(stamp_ns: int = 1_500_000_000):
    ts = store()
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="camera_color_optical_frame")


def image_cdr(rgb: np.ndarray, encoding: str = "rgb8", pad: int = 0, stamp_ns: int = 1_500_000_000) -> bytes:
    h, w = rgb.shape[:2]
    img = {"rgb8": rgb, "bgr8": rgb[..., ::-1], "mono8": rgb[..., :1]}[encoding]
    c = img.shape[2]
    rows = np.zeros((h, w * c + pad), np.uint8)
    rows[:, :w * c] = img.reshape(h, w * c)
    Image = store().types["sensor_msgs/msg/Image"]
    msg = Image(header=_header(stamp_ns), height=h, width=w, encoding=encoding, is_bigendian=0, step=w * c + pad,
                data=rows.ravel())
    return bytes(store().serialize_cdr(msg, "sensor_msgs/msg/Image"))


def compressed_cdr(rgb: np.ndarray, fmt: str = ".jpg") -> bytes:
    ok, data = cv2.imencode(fmt, rgb[..., ::-1])
    Compressed = store().types["sensor_msgs/msg/CompressedImage"]
    msg = Compressed(header=_header(), format="rgb8; jpeg compressed bgr8" if fmt == ".jpg" else "png",
                     data=np.frombuffer(data.tobytes(), np.uint8))
    return bytes(store().serialize_cdr(msg, "sensor_msgs/msg/CompressedImage"))


def info_cdr(K: np.ndarray, d: np.ndarray, w: int, h: int, model: str = "plumb_bob") -> bytes:
    ts = store()
    Info = ts.types["sensor_msgs/msg/CameraInfo"]
    Roi = ts.types["sensor_msgs/msg/RegionOfInterest"]
    P = np.hstack([K, np.zeros((3, 1))])
    msg = Info(header=_header(), height=h, width=w, distortion_model=model, d=np.asarray(d, float),
               k=K.ravel().astype(float), r=np.eye(3).ravel(), p=P.ravel(), binning_x=0, binning_y=0,
               roi=Roi(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
    return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/CameraInfo"))


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return np.ascontiguousarray(cv2.imread(str(PHOTO))[..., ::-1])


def test_every_image_encoding_decodes_to_the_same_rgb(photo):
    small = photo[:50, :70]
    for enc, pad in (("rgb8", 0), ("bgr8", 6), ("mono8", 2)):
        rgb, stamp = decode_image(image_cdr(small, enc, pad))
        want = np.repeat(small[..., :1], 3, axis=2) if enc == "mono8" else small
        assert np.array_equal(rgb, want), enc
        assert stamp == 1_500_000_000
    png, _ = decode_compressed(compressed_cdr(small, ".png"))
    assert np.array_equal(png, small)
    jpg, _ = decode_compressed(compressed_cdr(photo))
    assert jpg.shape == photo.shape and np.abs(jpg.astype(int) - photo).mean() < 3.0


def test_camera_info_gives_intrinsics_and_distortion_and_bad_messages_are_named():
    K = np.array([[610.0, 0, 321.0], [0, 611.0, 239.0], [0, 0, 1]])
    cal = decode_camera_info(info_cdr(K, [-0.1, 0.02, 0, 0, 0], 640, 480))
    assert np.allclose(cal.K, K) and cal.dist[0] == -0.1 and (cal.width, cal.height) == (640, 480)
    with pytest.raises(FrameError, match="no usable K"):
        decode_camera_info(info_cdr(np.zeros((3, 3)), [], 640, 480))
    with pytest.raises(FrameError, match="distortion_model 'equidistant'"):
        decode_camera_info(info_cdr(K, [0, 0, 0, 0], 640, 480, "equidistant"))
    with pytest.raises(FrameError, match="not a sensor_msgs/msg/Image"):
        decode_image(b"\x00\x01\x00\x00garbage")
    Image = store().types["sensor_msgs/msg/Image"]
    odd = Image(header=_header(), height=2, width=2, encoding="16UC1", is_bigendian=0, step=4,
                data=np.zeros(8, np.uint8))
    with pytest.raises(FrameError, match="encoding '16UC1' is not read"):
        decode_image(bytes(store().serialize_cdr(odd, "sensor_msgs/msg/Image")))
    assert info_topic("/camera/color/image_raw/compressed") == "/camera/color/camera_info"


def test_a_ros_image_topic_through_the_bridge_is_a_frame_with_the_cameras_own_intrinsics(tmp_path, photo):
    creds = tmp_path / "credentials"
    make_credentials(creds)
    rid = f"ros{free_port()}"
    ep = f"tls/127.0.0.1:{free_port()}"

    def settings(role, **kw):
        return ZenohSettings(robot_id=rid, identity=str(identity_folder(creds, role)), access_control=True,
                             gossip=False, **kw)

    K = np.array([[900.0, 0, 579.5], [0, 900.0, 434.5], [0, 0, 1]])
    with ServiceNode("bridge", settings("bridge", listen=(ep,))) as bridge, \
            ServiceNode("perception", settings("perception", connect=(ep,))) as perception:
        source = RosImageSource(perception, "/camera/color/image_raw",
                                PerceptionParams(source="ros:/camera/color/image_raw"))
        try:
            wait_subscribed(bridge.session, "camera/color/image_raw")
            wait_subscribed(bridge.session, "camera/color/camera_info")
            image = image_cdr(photo, "bgr8")
            frame = None
            deadline = time.monotonic() + 10.0
            while frame is None and time.monotonic() < deadline:  # camera_info first, as a driver latches it
                bridge.session.put("camera/color/camera_info", info_cdr(K, [0, 0, 0, 0, 0], 1160, 870))
                time.sleep(0.05)
                bridge.session.put("camera/color/image_raw", image)
                if source.calibration is not None:  # an image put meanwhile may still be on its way: wait for one
                    end = time.monotonic() + 2.0
                    while frame is None and time.monotonic() < end:
                        frame = source.read()
                        time.sleep(0.01)
                else:
                    frame = source.read()
            assert frame is not None and np.array_equal(frame.rgb, photo)
            assert np.allclose(frame.K, K) and abs(frame.t_s - 1.5) < 1e-9
            # a payload over the size bound is dropped before decoding, counted
            import perception.ros_images as ri

            bound, ri.MAX_IMAGE_BYTES = ri.MAX_IMAGE_BYTES, len(image) - 1
            try:
                bridge.session.put("camera/color/image_raw", image)
                wait_for(lambda: source.read() is None and source.counters["frames_bad: image over the size bound"],
                         5.0, "the oversized image counted")
            finally:
                ri.MAX_IMAGE_BYTES = bound
            # a perception identity may not put on the camera's keys: the bridge and the robot side only
            rogue = []
            sub = bridge.session.declare_subscriber("camera/**", lambda s: rogue.append(s))
            wait_subscribed(perception.session, "camera/color/image_raw")
            perception.session.put("camera/color/image_raw", image)
            time.sleep(0.3)
            assert rogue == []
            sub.undeclare()
        finally:
            source.close()


def test_the_ros_source_is_named_in_the_source_setting():
    from interfaces.errors import ConfigError

    assert PerceptionParams(source="ros:/camera/color/image_raw/compressed").source.startswith("ros:")
    with pytest.raises(ConfigError, match="ros:TOPIC"):
        PerceptionParams(source="ros:not a topic")
