"""Perception's self-filter: the robot's tool projected from the camera onto the board and masked out."""

from __future__ import annotations

import numpy as np
import pytest

from arm.description import ERASER_DEPTH_M, PAD_SIZE_M
from arm.robot_model import RobotModel
from interfaces.transforms import transform
from perception.classify import InkClassifier
from perception.params import InkParams, PerceptionParams
from perception.rectify import BoardGrid
from perception.self_filter import ToolTrack, board_shadow, shadow_mask, tool_corners
from sim.board import SEED_Q_RAD

#: A board in the world: origin (1, 2, 0.5), x along world y, y along world -x, z up.
T_BOARD = transform(np.column_stack([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), np.array([1.0, 2.0, 0.5]))


def _world(xyz_board) -> np.ndarray:
    return np.asarray(xyz_board, float) @ T_BOARD[:3, :3].T + T_BOARD[:3, 3]


def test_tool_box_is_the_pad_with_the_holder_behind_it():
    R = np.column_stack([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # pad facing down (tool z down)
    c = tool_corners(np.array([0.3, -0.1, 0.2]), R)
    assert c.shape == (8, 3)
    np.testing.assert_allclose(np.sort(np.unique(np.round(c[:, 2], 9))), [0.2, 0.2 + ERASER_DEPTH_M])
    np.testing.assert_allclose(np.ptp(c[:, 0]), PAD_SIZE_M[1])  # tool y along world x
    np.testing.assert_allclose(np.ptp(c[:, 1]), PAD_SIZE_M[0])


def test_shadow_of_points_on_the_board_is_themselves_and_grows_with_their_height():
    camera = _world([0.3, 0.2, 1.0])
    on_board = _world([[0.1, 0.1, 0.0], [0.5, 0.4, 0.0]])
    np.testing.assert_allclose(board_shadow(on_board, T_BOARD, camera), [[0.1, 0.1], [0.5, 0.4]], atol=1e-12)
    # 0.25 m up, straight below the camera's 1 m: away from the camera's foot by 1 / (1 - 0.25)
    up = _world([[0.3, 0.2, 0.25], [0.4, 0.2, 0.25]])
    np.testing.assert_allclose(board_shadow(up, T_BOARD, camera), [[0.3, 0.2], [0.3 + 0.1 / 0.75, 0.2]],
                               atol=1e-12)


def test_points_level_with_or_behind_the_camera_and_a_camera_behind_the_board_give_no_shadow():
    camera = _world([0.3, 0.2, 1.0])
    pts = _world([[0.1, 0.1, 1.0], [0.1, 0.1, 1.5], [0.2, 0.2, 0.5]])
    assert board_shadow(pts, T_BOARD, camera).shape == (1, 2)
    assert board_shadow(pts, T_BOARD, _world([0.3, 0.2, -0.5])).shape == (0, 2)


def test_shadow_mask_fills_the_hull_grown_by_the_margin():
    grid = BoardGrid((0.4, 0.3), 0.002)
    square = np.array([[0.1, 0.1], [0.2, 0.1], [0.2, 0.2], [0.1, 0.2], [0.15, 0.15]])  # an inner point too
    m = shadow_mask(grid, square, 0.0)
    assert m.shape == grid.shape and m.dtype == bool
    assert m.sum() * 0.002 ** 2 == pytest.approx(0.01, rel=0.05)
    rows, cols = np.nonzero(m)
    xy = grid.xy_of(rows, cols)
    assert xy.min(axis=0) == pytest.approx([0.1, 0.1], abs=0.003)
    assert xy.max(axis=0) == pytest.approx([0.2, 0.2], abs=0.003)
    grown = shadow_mask(grid, square, 0.01)
    assert grown.sum() * 0.002 ** 2 == pytest.approx(0.12 ** 2 - (4 - np.pi) * 0.01 ** 2, rel=0.05)
    assert not shadow_mask(grid, square[:2], 0.01).any()
    # a grazing ray far off the board: still drawn, clipped
    far = np.array([[0.1, 0.1], [50.0, 0.1], [0.1, 0.2]])
    assert shadow_mask(grid, far, 0.0)[grid.shape[0] // 2:].any()


def test_hidden_pixels_are_occluded_whatever_their_colour():
    params = InkParams()
    img = np.tile(np.array((205, 205, 201), np.uint8), (60, 80, 1))
    ink_colour = np.array(params.inks["blue"]) * np.array([205.0, 205.0, 201.0]) / np.array(params.board_rgb)
    img[20:40, 20:50] = np.round(ink_colour).astype(np.uint8)  # ink, or a tool the colour of ink
    clf = InkClassifier(params, np.ones((60, 80), bool), 0.002)
    assert clf.classify(img).stain[22:38, 22:48].all()
    hidden = np.zeros((60, 80), bool)
    hidden[18:42, 18:52] = True
    ink = clf.classify(img, hidden)
    assert ink.occluded[18:42, 18:52].all() and not ink.stain.any() and ink.d[hidden].max() == 0.0
    assert not ink.occluded[:, 60:].any()


def test_tool_track_takes_the_state_nearest_the_frame_and_nothing_stale():
    model = RobotModel()
    track = ToolTrack(max_age_s=0.05)
    assert track.corners_at(1_000_000_000, 0.0) is None and track.unknown == 1
    q1, q2 = SEED_Q_RAD.copy(), SEED_Q_RAD + 0.2
    track.add(1_000_000_000, q1.tolist(), 10.0)
    track.add(1_010_000_000, q2.tolist(), 10.01)
    track.add(1_020_000_000, [0.0] * 6, 10.02)  # not this arm: ignored
    track.add(1_030_000_000, [float("nan")] * 7, 10.03)  # ignored
    np.testing.assert_allclose(track.corners_at(1_003_000_000, 10.1), tool_corners(*model.tcp_pose(q1)))
    np.testing.assert_allclose(track.corners_at(1_008_000_000, 10.1), tool_corners(*model.tcp_pose(q2)))
    assert track.corners_at(1_200_000_000, 10.1) is None  # 0.19 s from the newest state
    # a frame without the robot's clock: the newest state, if it arrived recently
    np.testing.assert_allclose(track.corners_at(0, 10.05), tool_corners(*model.tcp_pose(q2)))
    assert track.corners_at(0, 10.2) is None
    assert (track.used, track.unknown) == (3, 3)


def test_the_mask_and_its_params_are_checked():
    with pytest.raises(Exception, match="tool_mask"):
        PerceptionParams.from_table({"tool_mask": "yes"})
    with pytest.raises(Exception, match="tool_margin_m"):
        PerceptionParams.from_table({"tool_margin_m": 0.5})
    assert PerceptionParams().tool_mask is True
