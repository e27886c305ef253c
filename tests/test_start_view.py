"""The arm's start pose must leave perception the markers it needs, checked against the camera's own image."""

from __future__ import annotations

import os
import tempfile

import cv2
import numpy as np
import pybullet as pb
import pytest

from arm.robot_model import RobotModel
from interfaces.errors import ConfigError
from perception.board import detect_markers, make_detector
from sim.analytic_camera import AnalyticCamera
from sim.board import board_from_params, start_configuration
from sim.board_sampler import board_refusal, sample_board
from sim.camera import board_texture, camera_pose, intrinsics_of, light_towards, marker_layer
from sim.core import SimCore
from sim.params import SimParams
from sim.start_view import MARKERS_NEEDED, markers_hidden_at_start, start_view_problem
from sim.world import build_world

#: Random board 636 as the sampler drew it before it checked the start view: the cell waited for a board pose
#: until its wall-time limit, perception reporting "only markers [1, 2] seen (need 3)" on every frame.
BOARD_636 = {"preset": "custom", "origin_m": [0.439928, 0.47951, 0.044058],
             "quat_wxyz": [0.691996258, 0.549140389, -0.418743957, -0.210331907], "size_m": [0.8766, 0.4509]}


def _markers_in_the_image(params: SimParams, model: RobotModel) -> tuple[set[int], list[int]]:
    """(markers the detector finds in the camera's image of the arm at its start pose, those the check hides)."""
    board = board_from_params(params.board)
    q0 = start_configuration(board, params.start_standoff_m, model)
    T = camera_pose(params.camera, board)
    client = pb.connect(pb.DIRECT)
    try:
        world = build_world(client, board, params.contact, q0, visual=True)
        texture = board_texture(np.zeros((2, 2)), params.dirt.cell_m, marker_layer(board.size_m), board.size_m)
        with tempfile.TemporaryDirectory() as tmp:  # the board's face as the cell's renderer puts it on
            path = os.path.join(tmp, "board.png")
            cv2.imwrite(path, texture[..., ::-1])
            pb.changeVisualShape(world.board, -1, textureUniqueId=pb.loadTexture(path, physicsClientId=client),
                                 physicsClientId=client)
        cam = AnalyticCamera(world, params.camera, intrinsics_of(params.camera), T,
                             np.asarray(light_towards(params.camera, board)), board.origin_m, board.normal_world)
        rgb = np.zeros((params.camera.height, params.camera.width, 3), np.uint8)
        cam.render(rgb, q0)
    finally:
        pb.disconnect(client)
    found = set(detect_markers(make_detector(), cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)))
    return found, markers_hidden_at_start(board, q0, T[:3, 3], model)


def test_a_start_pose_that_hides_the_markers_is_refused_by_name_as_the_camera_sees_it():
    model = RobotModel()
    params = SimParams.from_table({"board": BOARD_636, "seed": 636, "dirt": {"stains": 1}})
    found, hidden = _markers_in_the_image(params, model)
    assert found == {1, 2}, "the camera's image: as the campaign's cell saw it"
    assert hidden == [0, 3]
    why = board_refusal(BOARD_636, model, 636)
    assert why is not None and "hides markers [0, 3]" in why and f"needs {MARKERS_NEEDED}" in why
    with pytest.raises(ConfigError, match=r"impossible start: the arm at its start pose hides markers \[0, 3\]"):
        SimCore(params, model)
    draw = sample_board(636, model)
    assert draw.table != BOARD_636 and any("hides markers [0, 3]" in why for why in draw.refused)


@pytest.mark.parametrize("seed", [241, 263])
def test_a_marker_the_arm_grazes_is_still_counted_in_view(seed):
    """Boards 241 and 263: the arm's capsules cover a corner or two of marker 3 at the start pose; the detector
    finds it, and the check counts it in view (the cells cleaned)."""
    model = RobotModel()
    table = sample_board(seed, model).table
    params = SimParams.from_table({"board": table, "seed": seed, "dirt": {"stains": 1 + seed % 6}})
    found, hidden = _markers_in_the_image(params, model)
    assert len(found) >= MARKERS_NEEDED and not set(hidden) & found
    board = board_from_params(params.board)
    q0 = start_configuration(board, params.start_standoff_m, model)
    assert start_view_problem(board, q0, camera_pose(params.camera, board)[:3, 3], model) is None
