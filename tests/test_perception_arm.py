"""The whole arm masked from its joint states (perception/arm_mask.py): a real iiwa's light grey links, dark
joints, wrist and cable (the analytic camera's ``look="iiwa"``) pass over a stain without a false stain or a
false kappa, and a delayed state's mask still covers the arm."""

from __future__ import annotations

import numpy as np
import pytest

from arm.robot_model import RobotModel
from perception.arm_mask import ArmSilhouette, ArmState
from perception.frames import Frame, camera_matrix
from perception.params import PerceptionParams
from perception.pipeline import Perception
from perception.rectify import BoardGrid
from sim.analytic_camera import AnalyticCamera
from sim.camera import composite_dirt

from .test_analytic_camera import Scene

#: Frame rate of the sweep [Hz], the wrist's speed over the board [m/s] and its height over the board [m].
RATE_HZ, SPEED_M_S, HOVER_M = 10.0, 0.34, 0.08


@pytest.fixture(scope="module")
def scene():
    s = Scene("wall")
    s.iiwa = AnalyticCamera(s.world, s.cam, s.k, s.T, s.light, s.core.board.origin_m, s.core.board.normal_world,
                            look="iiwa")
    yield s
    s.close()


def sweep(scene, model: RobotModel, centre_board_m: np.ndarray) -> list[np.ndarray]:
    """Joint positions of a pass of the pad ``HOVER_M`` in front of the board, over ``centre_board_m`` as the
    camera sees it, along the board's x, at ``SPEED_M_S`` and ``RATE_HZ``."""
    board = scene.core.board
    _, R = model.tcp_pose(scene.core.q_start)
    qs, q = [], scene.core.q_start
    step = SPEED_M_S / RATE_HZ
    o = scene.T[:3, 3]
    for dx in np.arange(-0.2, 0.2 + 1e-9, step):
        on_board = board.world_from_board(np.array([centre_board_m[0] + dx, centre_board_m[1]]))
        # on the camera's ray through that board point, HOVER_M in front of the board: the pad hides the point
        p = on_board + (o - on_board) * HOVER_M / float((o - on_board) @ board.normal_world)
        q = model.solve_ik(p, R, q, tol_m=1e-3)
        qs.append(q)
    return qs


def frame_of(scene, camera: AnalyticCamera, q: np.ndarray) -> np.ndarray:
    rgb = np.zeros((scene.cam.height, scene.cam.width, 3), np.uint8)
    visible = camera.render(rgb, q)
    composite_dirt(rgb, visible, scene.cells, scene.core.dirt.dirt)
    return rgb


@pytest.mark.parametrize("inks", [None, {"blue": [28, 38, 96], "black": [40, 40, 42]}],
                         ids=["simulator", "with black ink"])
def test_the_wrist_passing_over_a_stain_makes_no_stain_and_no_kappa(scene, inks):
    model = RobotModel()
    stains = scene.core.dirt.stains
    target = np.asarray(stains[0].centre_m, float)
    qs = sweep(scene, model, target)
    K = camera_matrix(scene.k)
    parked = [scene.core.q_start] * 6  # the stains confirmed first, the arm where the run starts
    perception = Perception(PerceptionParams.from_table({"ink": {"inks": inks}} if inks else {}))
    covered = 0
    out = None
    least_seen = 1.0
    for n, (q, q_next) in enumerate(zip(parked + qs, parked[1:] + qs + [qs[-1]])):
        image = frame_of(scene, scene.iiwa, q)
        covered += int(n >= len(parked) and (scene.iiwa._arm.reshape(-1) > 0).sum() > 0)
        arm = ArmState(q, (q_next - q) * RATE_HZ, 0.0)
        r = perception.process(Frame(image, K, scene.T, n / RATE_HZ, n + 1), arm=arm)
        out = r.stains or out
        for s in (r.stains.stains if r.stains is not None else []):
            near = min(np.linalg.norm(np.subtract(s.centre_board_m, t.centre_m)) for t in stains)
            assert near < 0.03, f"frame {n}: a stain at {s.centre_board_m} where there is none"
            assert not s.kappa, f"frame {n}: kappa for stain {s.id}, which nobody wiped"
            assert s.remaining > 0.5, (n, s.id, s.remaining)
            if np.linalg.norm(np.subtract(s.centre_board_m, target)) < 0.03:
                least_seen = min(least_seen, s.visible)
    assert covered >= len(qs) // 2
    assert least_seen < 0.5  # the arm did hide the stain; its pixels were occluded, never judged clean
    assert len(out.stains) == len(stains)


def test_the_arm_crossing_over_a_stain_again_and_again_is_no_pass_of_the_pad_and_no_smear(scene):
    """Random board 303: the arm, wiping stains 6-11 cm away, hid a stain from the camera and uncovered it eight
    times; each return counted as a pass without progress and the stain was given up as smeared before the pad
    touched it (perception/smear.py). With the tool's pose a return is a pass only when the pad's face was on
    the board over the stain; the same frames without it count every return, as where the pad is not known."""
    from perception.self_filter import tool_corners

    model = RobotModel()
    target = np.asarray(scene.core.dirt.stains[0].centre_m, float)
    qs = sweep(scene, model, target)
    K = camera_matrix(scene.k)
    parked = [scene.core.q_start] * 6
    path = parked + (qs + [scene.core.q_start] * 2) * 4  # four crossings 8 cm in front of the board
    images = [frame_of(scene, scene.iiwa, q) for q in path]
    seen = {}
    for with_tool in (True, False):
        perception = Perception(PerceptionParams())
        last = None
        for n, (q, image) in enumerate(zip(path, images)):
            tool = tool_corners(*model.tcp_pose(q)) if with_tool else None
            r = perception.process(Frame(image, K, scene.T, n / RATE_HZ, n + 1), tool,
                                   ArmState(q, np.zeros(7), 0.0))
            for s in (r.stains.stains if r.stains is not None else []):
                if np.linalg.norm(np.subtract(s.centre_board_m, target)) < 0.03:
                    last = s
        assert last is not None
        seen[with_tool] = (last.passes, last.smeared)
    assert seen[True] == (0, False), seen
    assert seen[False][0] >= 3 and seen[False][1], seen  # every return a pass: three without progress, a smear


def test_the_iiwa_looks_as_it_does_light_links_dark_joints(scene):
    q = scene.core.q_start
    frame_of(scene, scene.iiwa, q)
    colours = scene.iiwa.mesh.face_rgb
    assert (colours.mean(axis=1) > 200).sum() > 0 and (colours.mean(axis=1) < 60).sum() > 0


def test_the_mask_follows_a_delayed_state():
    """The state 50 ms older than the frame, the arm moving: the mask grown by age x speed covers where the arm
    is at the frame's time; without the growth it would not."""
    from sim.board import board_from_params
    from sim.params import BoardParams

    board = board_from_params(BoardParams(preset="wall"))
    grid = BoardGrid(tuple(board.size_m), 0.002)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = board.R, board.origin_m
    camera = board.world_from_board(np.array([0.4, 0.3])) + 1.2 * board.normal_world
    arm = ArmSilhouette()
    model = RobotModel()
    _, R = model.tcp_pose(np.array([0.0, 0.6, 0.0, -1.2, 0.0, 0.8, 0.0]))
    q0 = model.solve_ik(board.world_from_board(np.array([0.3, 0.3])) + 0.08 * board.normal_world, R,
                        np.array([0.0, 0.6, 0.0, -1.2, 0.0, 0.8, 0.0]), tol_m=1e-3)
    q1 = model.solve_ik(board.world_from_board(np.array([0.3 + 0.34 * 0.05, 0.3])) + 0.08 * board.normal_world, R,
                        q0, tol_m=1e-3)
    dq = (q1 - q0) / 0.05
    now = arm.board_mask(grid, T, camera, ArmState(q1, dq, 0.0), 0.0)
    delayed = arm.board_mask(grid, T, camera, ArmState(q0, dq, 0.05), 0.0)
    bare = arm.board_mask(grid, T, camera, ArmState(q0, np.zeros(7), 0.0), 0.0)
    assert now.sum() > 1000
    assert (now & ~delayed).sum() <= 0.001 * now.sum()  # covered, to the outline's pixels
    assert (now & ~bare).sum() > 0.01 * now.sum()  # the stale silhouette alone misses part of the arm
    assert arm.margin_m(ArmState(q0, dq, 0.05), 0.01) == pytest.approx(
        0.01 + 0.05 * arm.fastest_point_m_s(q0, dq))
    assert arm.fastest_point_m_s(q0, dq) >= 0.3  # the pad moves at 0.34 m/s
