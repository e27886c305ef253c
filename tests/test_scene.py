"""What Foxglove draws of the cell (launch/scene.py): transforms from the URDF, the board, stains, camera overlays."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from arm.robot_model import RobotModel
from interfaces.keys import Keys
from interfaces.messages import CameraFrame, CameraIntrinsics, Capabilities, Pose, RobotState, StainObservation, Stains
from launch.record import McapSink
from launch.scene import TF_PERIOD_S, SceneBuilder, ellipse_on_board, project, urdf_visuals

from .mcap_check import check_recording, protobuf_class

KEYS = Keys()
CAMERA_KEY = KEYS.camera_frame("board")


def _read(msg):
    """A foxglove-sdk message (write-only) as the protobuf message Foxglove decodes, fields readable."""
    schema = type(msg).get_schema()
    return protobuf_class(schema.name, bytes(schema.data)).FromString(msg.encode())


def _out(pairs) -> dict:
    return {t: _read(m) for t, m in pairs}


def _state(q, t_ns: int) -> RobotState:
    return RobotState(seq=1, stamp_ns=t_ns, q_rad=list(q), dq_rad_s=[0.0] * 7, tau_nm=[0.0] * 7,
                      wrench_world=[0.0] * 6, capabilities=Capabilities(True, [100.0] * 7, "sim", 1000.0),
                      robot_time_ns=t_ns)


def _pose(p, R) -> Pose:
    q = pin.Quaternion(np.asarray(R, float)).normalized()
    return Pose(position_m=[float(v) for v in p], quat_wxyz=[q.w, q.x, q.y, q.z])


def camera_message(t_ns: int = 0) -> CameraFrame:
    """A blank 640x480 mono8 CameraFrame at (0, 0, 0.5) m looking along +x, stamped ``t_ns``."""
    # 1 m in front of a board in the world's y-z plane, looking along +x (optical: x right = -y, y down = -z)
    R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    k = CameraIntrinsics(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=640, height=480)
    return CameraFrame(seq=1, stamp_ns=t_ns, camera="board", encoding="mono8", data=bytes(640 * 480), intrinsics=k,
                       T_camera_to_world=_pose((0.0, 0.0, 0.5), R), robot_time_ns=t_ns)


def stains_message(kappa=(False, True)) -> Stains:
    """A Stains message with one stain per entry of ``kappa`` (its kappa flag) on a board in the world's y-z plane."""
    # board frame: origin at the corner (1, 0.3, 0.3) in the world, x along -y, y along +z, z towards the camera
    Rb = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    obs = [StainObservation(id=i, centre_board_m=[0.3, 0.2], centre_world_m=[1.0, 0.0, 0.5], size_m=0.1,
                            extent_board_m=[0.1, 0.05], remaining=0.5, visible=1.0, kappa=k)
           for i, k in enumerate(kappa)]
    return Stains(seq=1, stamp_ns=5, T_board_to_world=_pose((1.0, 0.3, 0.3), Rb), board_size_m=[0.6, 0.4],
                  stains=obs, robot_time_ns=5)


def test_link_transforms_are_the_urdf_forward_kinematics_and_come_at_50_hz():
    b = SceneBuilder(KEYS)
    q = np.array([0.3, -0.5, 0.2, -1.4, 0.1, 0.9, -0.4])
    first = b.on_message(KEYS.robot_state, _state(q, 10**9), 0)
    assert [t for t, _ in first] == [b.topic_tf, b.topic_robot]
    tfs = {t.child_frame_id: t for t in _read(first[0][1]).transforms}
    assert {"iiwa_link_0", "iiwa_link_7", "tcp"} <= set(tfs) and all(t.parent_frame_id == "world" for t in
                                                                        tfs.values())
    p, R = RobotModel().tcp_pose(q)
    pad = tfs["tcp"]
    assert np.allclose([pad.translation.x, pad.translation.y, pad.translation.z], p, atol=1e-9)
    qpad = pin.Quaternion(R)
    assert abs(abs(np.dot([pad.rotation.x, pad.rotation.y, pad.rotation.z, pad.rotation.w],
                          [qpad.x, qpad.y, qpad.z, qpad.w])) - 1) < 1e-9
    # the next state 1 ms later makes nothing; one 20 ms later makes transforms (no geometry again so soon)
    assert b.on_message(KEYS.robot_state, _state(q, 10**9 + 10**6), 0) == []
    later = b.on_message(KEYS.robot_state, _state(q, 10**9 + int(TF_PERIOD_S * 1e9)), 0)
    assert [t for t, _ in later] == [b.topic_tf]


def test_the_arm_geometry_is_every_visual_of_the_urdf_in_its_link_frame():
    visuals = urdf_visuals()
    assert len(visuals) == 10 and {v.kind for v in visuals} == {"cylinder", "cube"}
    scene = _read(SceneBuilder(KEYS).arm_geometry(0))
    assert sum(len(e.cylinders) + len(e.cubes) for e in scene.entities) == len(visuals)
    assert all(e.frame_locked and e.frame_id == e.id.split("/", 1)[1] for e in scene.entities)


def test_the_board_and_each_stain_coloured_by_kappa_replacing_what_was_drawn():
    b = SceneBuilder(KEYS)
    out = _out(b.on_message(KEYS.perception_stains, stains_message(), 0))
    board = out[b.topic_board]
    assert len(board.deletions) == 1 and board.deletions[0].type == 1  # ALL
    ids = [e.id for e in board.entities]
    assert ids == ["board", "stain/0", "stain/1"]
    red, green = board.entities[1].lines[0].color, board.entities[2].lines[0].color
    assert red.r > red.g and green.g > green.r
    assert "kappa" in board.entities[2].texts[0].text and "50%" in board.entities[1].texts[0].text
    tf = out[b.topic_tf].transforms[0]
    assert (tf.parent_frame_id, tf.child_frame_id) == ("world", "board")
    assert (tf.translation.x, tf.translation.y, tf.translation.z) == pytest.approx((1.0, 0.3, 0.3))


def test_stain_outlines_are_projected_into_the_camera_image():
    f = camera_message()
    # a point on the optical axis lands on the principal point, one 0.1 m to the right at 1 m depth 50 px right
    uv, ok = project(np.array([[1.0, 0.0, 0.5], [1.0, -0.1, 0.5], [-1.0, 0.0, 0.5]]), f)
    assert ok.tolist() == [True, True, False]
    assert uv[0] == pytest.approx((320.0, 240.0)) and uv[1] == pytest.approx((370.0, 240.0))
    b = SceneBuilder(KEYS)
    out = _out(b.on_message(CAMERA_KEY, f, 0))
    tf = out[f"{KEYS.prefix}/scene/tf"].transforms[0]
    assert tf.child_frame_id == "camera_board" != "board"  # a camera named like the board is not the board
    cal = out[f"{CAMERA_KEY}/calibration"]
    assert (cal.width, cal.height, cal.frame_id) == (640, 480, "camera_board")
    assert list(cal.K)[:3] == [500.0, 0.0, 320.0]
    ann = _out(b.on_message(KEYS.perception_stains, stains_message(), 0))[f"{CAMERA_KEY}/annotations"]
    assert len(ann.points) == 2 and len(ann.texts) == 2
    # stain centre (0.3, 0.2) on the board -> world (1.0, 0.0, 0.5): the principal point; extents 0.1 x 0.05 m at
    # 1 m -> an ellipse 50 px wide and 25 px tall around it
    pts = np.array([(p.x, p.y) for p in ann.points[0].points])
    assert pts.mean(axis=0) == pytest.approx((320.0, 240.0), abs=1e-6)
    assert np.ptp(pts[:, 0]) == pytest.approx(50.0, rel=0.01) and np.ptp(pts[:, 1]) == pytest.approx(25.0, rel=0.01)
    ring = ellipse_on_board([0.3, 0.2], [0.1, 0.05])
    assert ring.shape == (32, 3) and np.allclose(ring.mean(axis=0), (0.3, 0.2, 0.0))


def test_the_scene_is_recorded_as_foxglove_typed_messages_that_parse_with_their_schemas(tmp_path):
    b = SceneBuilder(KEYS)
    path = tmp_path / "s.mcap"
    sink = McapSink(path)
    for i, (key, msg) in enumerate([(KEYS.robot_state, _state(np.zeros(7), 0)), (CAMERA_KEY, camera_message()),
                                    (KEYS.perception_stains, stains_message())]):
        for topic, m in b.on_message(key, msg, i):
            sink.write_typed(topic, m, i)
    sink.finish()
    channels = check_recording(path, every=1)
    assert {name for name, _ in channels.values()} == {"foxglove.FrameTransforms", "foxglove.SceneUpdate",
                                                       "foxglove.CameraCalibration", "foxglove.ImageAnnotations"}


def test_the_layout_places_every_panel_once_and_the_file_is_current():
    import json

    from launch.layout import PANELS, cell_layout, layout_paths

    from .conftest import REPO

    def ids(node):
        return [node] if isinstance(node, str) else ids(node["first"]) + ids(node["second"])

    layout = cell_layout()
    assert sorted(ids(layout["layout"])) == sorted(layout["configById"]) == sorted(PANELS)
    assert json.loads((REPO / "config" / "foxglove" / "lamps.json").read_text()) == layout
    topics, paths = layout_paths(layout)
    assert {f"{KEYS.prefix}/scene/tf", f"{CAMERA_KEY}/annotations", f"{KEYS.controller_trace}/plot"} <= topics
    assert (KEYS.robot_command, "tau_nm", 6) in paths
    other = cell_layout(Keys.for_robot("left"), camera="side")
    assert other["configById"]["Image!camera"]["imageMode"]["imageTopic"] == "lamps/left/camera/side/frame"
