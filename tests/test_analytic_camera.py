"""The analytic camera (sim/analytic_camera.py) against PyBullet's TinyRenderer on the same scene and poses:
the board it leaves visible, the arm, the light and shadow, the markers and what perception makes of a frame."""

from __future__ import annotations

import os
import tempfile

import cv2
import numpy as np
import pybullet as pb
import pytest

from perception.board import detect_markers, make_detector
from perception.frames import Frame, camera_matrix
from perception.params import PerceptionParams
from perception.pipeline import Perception
from sim.analytic_camera import (
    AMBIENT,
    LIGHT_DISTANCE_M,
    SHADOW_KEEP,
    AnalyticCamera,
    box_mesh,
    cylinder_mesh,
    face_frames,
    shadow_on_plane,
)
from sim.camera import (
    BOARD_RGB,
    DirtCompositor,
    board_cell_index,
    board_texture,
    camera_pose,
    composite_dirt,
    intrinsics_of,
    light_towards,
    marker_layer,
    projection_matrix,
    view_matrix,
)
from sim.core import SimCore
from sim.params import SimParams
from sim.world import build_world

#: Poses: the start, and the start with each joint moved by up to 0.2 rad (seeded).
POSES = 4


class Scene:
    """One board's mirrored scene drawn both ways."""

    def __init__(self, preset: str, shadow: bool = True) -> None:
        self.params = SimParams.from_table({"board": {"preset": preset}, "camera": {"shadow": shadow}})
        self.core = SimCore(self.params)
        cam = self.cam = self.params.camera
        self.client = pb.connect(pb.DIRECT)
        self.world = build_world(self.client, self.core.board, self.params.contact, self.core.q_start, visual=True)
        texture = board_texture(np.zeros_like(self.core.dirt.dirt), self.params.dirt.cell_m,
                                marker_layer(self.core.board.size_m), self.core.board.size_m)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "board.png")
            cv2.imwrite(path, texture[..., ::-1])
            tex = pb.loadTexture(path, physicsClientId=self.client)
        pb.changeVisualShape(self.world.board, -1, textureUniqueId=tex, physicsClientId=self.client)
        self.k = intrinsics_of(cam)
        self.T = camera_pose(cam, self.core.board)
        self.light = np.asarray(light_towards(cam, self.core.board))
        self.cells = board_cell_index(self.k, self.T, self.core.board, self.params.dirt.cell_m,
                                      self.core.dirt.dirt.shape)
        self.analytic = AnalyticCamera(self.world, cam, self.k, self.T, self.light, self.core.board.origin_m,
                                       self.core.board.normal_world)
        rng = np.random.default_rng(7)
        self.poses = [self.core.q_start]
        while len(self.poses) < POSES:  # the arm in front of the board, as in a run (the pad presses on it)
            q = self.core.q_start + rng.uniform(-0.2, 0.2, 7)
            if self.depth_behind_board_m(q) < 1e-3:
                self.poses.append(q)

    def depth_behind_board_m(self, q: np.ndarray) -> float:
        """How far the arm's deepest vertex over the board lies behind its front face at ``q`` [m] (< 0: in front;
        the robot's base may be below a table board's plane, beside the board)."""
        m, board = self.analytic.mesh, self.core.board
        R, p = self.analytic.link_poses(q)
        verts = np.einsum("vij,vj->vi", R[m.vertex_link], m.vertices) + p[m.vertex_link]
        local = (verts - board.origin_m) @ board.R
        over = np.all((local[:, :2] > -0.02) & (local[:, :2] < board.size_m + 0.02), axis=1)
        return float(-local[over, 2].min()) if over.any() else -1.0

    def tiny(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TinyRenderer's image (H, W, 3) with the dirt, and its segmentation (H * W,)."""
        for j, qj in zip(self.world.joints, q):
            pb.resetJointState(self.world.robot, j, float(qj), physicsClientId=self.client)
        cam = self.cam
        out = pb.getCameraImage(cam.width, cam.height, view_matrix(self.T), projection_matrix(self.k),
                                renderer=pb.ER_TINY_RENDERER, shadow=int(cam.shadow),
                                lightDirection=self.light.tolist(), physicsClientId=self.client)
        rgb = np.asarray(out[2], np.uint8).reshape(cam.height, cam.width, 4)[..., :3].copy()
        seg = np.asarray(out[4]).reshape(-1).copy()
        composite_dirt(rgb, seg == self.world.board, self.cells, self.core.dirt.dirt)
        return rgb, seg

    def drawn(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The analytic camera's image (H, W, 3) with the dirt, and its visible-board mask (H * W,)."""
        rgb = np.zeros((self.cam.height, self.cam.width, 3), np.uint8)
        visible = self.analytic.render(rgb, q)
        composite_dirt(rgb, visible, self.cells, self.core.dirt.dirt)
        return rgb, visible

    def close(self) -> None:
        pb.disconnect(self.client)
        self.core.close()


@pytest.fixture(scope="module", params=["wall", "table"])
def scene(request):
    s = Scene(request.param)
    yield s
    s.close()


def test_meshes_are_closed_convex_and_their_normals_point_out():
    for v, faces in (cylinder_mesh(0.07, 0.2, 12), box_mesh(np.array([0.12, 0.05, 0.03]))):
        centres, normals = face_frames(v, faces)
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
        assert np.all(np.einsum("fi,fi->f", centres, normals) > 0)  # outward
        for c, n in zip(centres, normals):  # convex: every vertex on or behind every face's plane
            assert np.all((v - c) @ n < 1e-12)
        edges = [tuple(sorted((f[i], f[(i + 1) % len(f)]))) for f in faces for i in range(len(f))]
        assert all(edges.count(e) == 2 for e in edges)  # closed: each edge shared by two faces


def test_a_point_on_the_plane_is_its_own_shadow_and_a_shadow_lies_on_the_line_from_the_light():
    o, n, light = np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([0.3, -0.2, 2.0])
    p = np.array([[0.1, 0.2, 0.0], [0.1, 0.2, 0.5], [-0.3, 0.4, 1.0]])
    s = shadow_on_plane(p, o, n, light)
    assert np.allclose(s[:, 2], 0.0) and np.allclose(s[0], p[0])
    for pi, si in zip(p[1:], s[1:]):
        assert np.allclose(np.cross(pi - light, si - light), 0.0)


def test_the_visible_board_and_the_arm_are_tinyrenderers_to_a_fraction_of_a_percent(scene):
    for q in scene.poses:
        _, seg = scene.tiny(q)
        _, visible = scene.drawn(q)
        board = seg == scene.world.board
        assert np.mean(board != visible) < 0.002, np.mean(board != visible)
        arm_tiny = seg == scene.world.robot
        arm = scene.analytic._arm.reshape(-1) > 0
        assert (arm_tiny & arm).sum() / (arm_tiny | arm).sum() > 0.95  # the arm occludes where it should
        assert arm.sum() > 5000
        shape, kernel = (scene.cam.height, scene.cam.width), np.ones((5, 5), np.uint8)
        for a, b in ((arm, arm_tiny), (arm_tiny, arm)):  # they differ only at the outline (polygon vs mesh)
            inner = cv2.erode(a.reshape(shape).astype(np.uint8), kernel).reshape(-1) > 0
            assert np.mean(b[inner]) > 0.995


def test_the_board_has_tinyrenderers_colours_and_the_arm_is_nothing_like_the_board(scene):
    q = scene.poses[0]
    tiny, seg = scene.tiny(q)
    drawn, visible = scene.drawn(q)
    both = (seg == scene.world.board) & visible & (scene.cells >= 0)
    clean = both & (scene.core.dirt.dirt.reshape(-1)[np.maximum(scene.cells, 0)] < 1e-3)
    a, t = drawn.reshape(-1, 3)[clean].astype(int), tiny.reshape(-1, 3)[clean].astype(int)
    values, counts = np.unique(t[:, 0], return_counts=True)
    lit = values[np.argmax(counts)]  # TinyRenderer's clean lit board (most of it)
    assert np.median(a[:, 0]) == lit
    shadowed = round(lit * (AMBIENT + SHADOW_KEEP * (lit / BOARD_RGB[0] - AMBIENT)) / (lit / BOARD_RGB[0]))
    assert set(np.unique(a[:, 0])) <= {lit, shadowed, lit - 1, shadowed - 1, lit + 1, shadowed + 1} | set(
        np.unique(t[:, 0]))  # markers and the frame come from TinyRenderer's own image
    arm = drawn.reshape(-1, 3)[scene.analytic._arm.reshape(-1) > 0].astype(float)
    assert np.median(arm.mean(axis=1)) < 0.8 * lit  # darker than the board: perception's occlusion


def test_the_arm_casts_its_shadow_where_the_light_says(scene):
    """Points on the arm's axis (link origins and the midpoints between them) seen from the light land on board
    points: those the arm leaves in view (and not at the shadow's edge) are shadowed in both images; a board
    corner far from the arm's shadow is lit in both."""
    from sim.camera import project

    board = scene.core.board
    light_m = LIGHT_DISTANCE_M * scene.light / np.linalg.norm(scene.light)
    h, w = scene.cam.height, scene.cam.width
    links = list(range(pb.getNumJoints(scene.world.robot, physicsClientId=scene.client)))
    seen = 0
    for q in scene.poses:
        tiny, seg = scene.tiny(q)
        drawn, visible = scene.drawn(q)
        far = np.round(project(scene.k, scene.T, board.world_from_board(board.size_m * [0.9, 0.9]))).astype(int)
        lit_a, lit_t = int(drawn[far[1], far[0], 0]), int(tiny[far[1], far[0], 0])
        assert abs(lit_a - lit_t) <= 1
        origins = np.array([s[4] for s in pb.getLinkStates(scene.world.robot, links, computeForwardKinematics=True,
                                                           physicsClientId=scene.client)])
        axis = np.vstack([origins, (origins[1:] + origins[:-1]) / 2])
        spots = np.round(project(scene.k, scene.T, shadow_on_plane(axis, board.origin_m, board.normal_world,
                                                                   light_m))).astype(int)
        for u, v in spots:
            if not (3 <= u < w - 3 and 3 <= v < h - 3):
                continue
            patch = ((v + np.arange(-3, 4))[:, None] * w + (u + np.arange(-3, 4))[None, :]).ravel()
            shadowed = drawn.reshape(-1, 3)[patch, 0].astype(int) < lit_a - 5
            if not (visible[patch].all() and (seg[patch] == scene.world.board).all() and shadowed.all()):
                continue  # hidden by the arm, off the board, or at the shadow's edge
            assert tiny[v, u, 0] < lit_t - 5, (u, v, tiny[v, u], lit_t)
            seen += 1
    assert seen >= 2


def test_no_shadow_when_the_camera_has_none():
    s = Scene("table", shadow=False)
    try:
        drawn, visible = s.drawn(s.poses[0])
        board = drawn.reshape(-1, 3)[visible & (s.cells >= 0)][:, 0]
        dirty = s.core.dirt.dirt.reshape(-1)[np.maximum(s.cells, 0)][visible & (s.cells >= 0)] > 1e-3
        values = np.unique(board[~dirty])
        assert values[-1] - values[0] > 100  # markers against white
        white = board[~dirty] > 128
        assert np.ptp(board[~dirty][white]) == 0  # one white: nothing shadowed
    finally:
        s.close()


def test_the_markers_are_found_where_tinyrenderer_shows_them(scene):
    detector = make_detector()
    for q in scene.poses[:2]:
        tiny, _ = scene.tiny(q)
        drawn, _ = scene.drawn(q)
        found_t = detect_markers(detector, cv2.cvtColor(tiny, cv2.COLOR_RGB2GRAY))
        found_a = detect_markers(detector, cv2.cvtColor(drawn, cv2.COLOR_RGB2GRAY))
        assert set(found_a) == set(found_t) and len(found_a) >= 3
        for mid in found_t:
            assert np.abs(found_a[mid] - found_t[mid]).max() < 0.5


def test_perception_finds_the_same_stains_in_both_images(scene):
    q = scene.poses[0]
    results = {}
    for name, image in (("tiny", scene.tiny(q)[0]), ("analytic", scene.drawn(q)[0])):
        perception = Perception(PerceptionParams())
        out = None
        for n in range(8):  # a stain is confirmed after 0.3 s of frames
            out = perception.process(Frame(image, camera_matrix(scene.k), scene.T, 0.1 * n, n)).stains or out
        results[name] = sorted(out.stains, key=lambda s: s.centre_board_m[0])
    tiny, drawn = results["tiny"], results["analytic"]
    assert len(drawn) == len(tiny) == len(scene.core.dirt.stains) or len(drawn) == len(tiny) >= 2
    for a, t in zip(drawn, tiny):
        assert np.linalg.norm(np.subtract(a.centre_board_m, t.centre_board_m)) < 0.005
        assert abs(a.size_m - t.size_m) < 0.1 * t.size_m
        assert abs(a.visible - t.visible) < 0.05


def test_the_renderers_dirt_compositor_tints_the_pixels_composite_dirt_tints(scene):
    """The renderer's per-scene compositor against the per-frame reference, pixel for pixel: the seeded stains,
    a board dirty nearly everywhere, a clean one, with the arm in front of the board."""
    compositor = DirtCompositor(scene.cells)
    rng = np.random.default_rng(3)
    q = scene.core.q_start + rng.uniform(-0.2, 0.2, 7)
    base = np.zeros((scene.cam.height, scene.cam.width, 3), np.uint8)
    visible = scene.analytic.render(base, q)
    assert 0 < visible.sum() < (scene.cells >= 0).sum()
    stains = scene.core.dirt.dirt
    assert (stains > 1e-3).any()
    for dirt, tinted in ((stains, True), (rng.random(stains.shape).astype(np.float32), True),
                         (np.zeros_like(stains), False)):
        want, got = base.copy(), base.copy()
        composite_dirt(want, visible, scene.cells, dirt)
        compositor(got, visible, dirt)
        assert np.array_equal(got, want)
        assert (not np.array_equal(got, base)) == tinted
