"""Perception's parts without networking or the simulator: clustering, colour model, kappa, board geometry, params."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from sklearn.cluster import DBSCAN

from interfaces.board_markers import marker_corners_board
from interfaces.errors import ConfigError
from interfaces.messages import CameraFrame, CameraIntrinsics, Pose
from perception.board import detect_markers, make_detector, measure_board, solve_pose
from perception.classify import InkClassifier
from perception.cluster import cluster_pixels
from perception.frames import FrameError, rgb_from_message
from perception.kappa import KappaLatch
from perception.params import InkParams, KappaParams, PerceptionParams, parse_source

# -- clustering ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("eps", [3.5, 6.5])  # off the grid distances sqrt(k)
def test_pixel_clustering_is_single_linkage_like_dbscan_with_one_sample(seed, eps):
    rng = np.random.default_rng(seed)
    mask = np.zeros((80, 100), bool)
    for _ in range(6):
        r, c = rng.integers(5, 75), rng.integers(5, 95)
        mask[max(r - rng.integers(1, 5), 0):r + rng.integers(1, 5),
             max(c - rng.integers(1, 5), 0):c + rng.integers(1, 5)] = True
    mask |= rng.random(mask.shape) < 0.01
    n, labels = cluster_pixels(mask, eps)
    pts = np.argwhere(mask)
    ours = labels[mask]
    finer = DBSCAN(eps=eps, min_samples=1).fit_predict(pts)
    coarser = DBSCAN(eps=eps + 1.5, min_samples=1).fit_predict(pts)
    # pixels within eps are always together; pixels farther apart than eps + 1.5 px (the grid) never are
    assert len(set(zip(finer.tolist(), ours.tolist()))) == len(set(finer.tolist()))
    assert len(set(zip(ours.tolist(), coarser.tolist()))) == n == len(set(ours.tolist()))
    assert len(set(coarser.tolist())) <= n <= len(set(finer.tolist()))


# -- colour model ----------------------------------------------------------------------------------------

def _board(rows=60, cols=80, white=(205, 205, 201)) -> np.ndarray:
    return np.tile(np.array(white, np.uint8), (rows, cols, 1))


def test_ink_fraction_is_recovered_under_any_light_and_shade():
    params = InkParams()
    clf = InkClassifier(params, np.ones((60, 80), bool), 0.002)
    for gain, shade in [(1.0, 1.0), (0.55, 1.0), (1.15, 0.9), (0.8, 0.85)]:
        white = np.array([205.0, 205.0, 201.0]) * gain
        # the ink in the same light as this white: params.inks["blue"] is the ink where the board is params.board_rgb
        ink_colour = np.array(params.inks["blue"]) * white / np.array(params.board_rgb)
        d_true = np.zeros((60, 80))
        d_true[20:40, 30:50] = np.linspace(0.0, 1.0, 20)[None, :]  # a ramp of ink
        # a pixel with a fraction d of ink averages the ink and the board (mixing by area, not the classifier's
        # absorption formula), then a soft shadow over part of the board and the ink
        img = (1 - d_true[..., None]) * white + d_true[..., None] * ink_colour
        img[:, 60:] *= shade
        ink = clf.classify(np.clip(img, 0, 255).round().astype(np.uint8))
        sel = ~ink.occluded[20:40, 30:50]
        assert sel.mean() > 0.9
        err = np.abs(ink.d[20:40, 30:50] - d_true[20:40, 30:50])[sel]
        assert err.max() < 0.05, (gain, shade, err.max())
        assert ink.stain[20:40, 30:50].sum() == pytest.approx((d_true[20:40, 30:50] >= 0.3).sum(), abs=20)


@pytest.mark.parametrize("name,rgb", [("grey arm", (91, 91, 94)), ("orange ring", (213, 89, 8)),
                                      ("eraser holder", (31, 51, 145)), ("felt", (50, 50, 50)),
                                      ("deep shadow", (120, 120, 118))])
def test_what_is_not_board_is_occluded_never_clean(name, rgb):
    img = _board()
    img[20:40, 20:50] = rgb
    ink = InkClassifier(InkParams(), np.ones(img.shape[:2], bool), 0.002).classify(img)
    assert ink.occluded[22:38, 22:48].all(), name
    assert not ink.stain[22:38, 22:48].any()
    assert not ink.occluded[:, 70:].any()  # the board beside it is judged


# -- kappa -----------------------------------------------------------------------------------------------

def test_kappa_needs_low_remaining_with_evidence_for_the_debounce_and_latches():
    k = KappaLatch(KappaParams(level=0.03, debounce_s=0.2, min_seen=0.9, reappear_margin=0.1))
    assert not k.update(0.0, 0.5, 1.0)
    assert not k.update(0.1, 0.01, 1.0)
    assert not k.update(0.2, 0.01, 0.5)  # half of it hidden: the count restarts
    assert not k.update(0.3, 0.01, 1.0)
    assert not k.update(0.4, 0.01, 1.0)
    assert k.update(0.5, 0.02, 1.0)  # 0.2 s below with evidence
    assert k.update(0.6, 0.10, 1.0)  # within the margin: stays
    assert k.update(0.7, 0.90, 0.2)  # hidden: no evidence either way
    assert k.update(0.8, 0.50, 1.0)
    assert not k.update(1.0, 0.50, 1.0)  # new ink, seen for the debounce time


# -- board geometry --------------------------------------------------------------------------------------

def _marker_image(size_m=(0.8, 0.6), hide=()):
    """A synthetic frontal-ish view of the board: (image, K, T_board_to_camera)."""
    K = np.array([[615.0, 0, 320], [0, 615.0, 240], [0, 0, 1]])
    R = cv2.Rodrigues(np.array([0.3, -0.25, 0.05]))[0] @ np.diag([1.0, -1.0, -1.0])  # board z towards the camera
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ np.array([size_m[0] / 2, size_m[1] / 2, 0.0]) + np.array([0.0, 0.0, 1.1])
    res = 0.001
    W, H = int(size_m[0] / res), int(size_m[1] / res)
    board = np.full((H, W), 240, np.uint8)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    for mid, c in marker_corners_board(size_m).items():
        if mid in hide:
            continue
        side = int(round((c[1, 0] - c[0, 0]) / res))
        img = cv2.aruco.generateImageMarker(dictionary, mid, side)
        r0, c0 = int(round(H - c[0, 1] / res)), int(round(c[0, 0] / res))
        board[r0:r0 + side, c0:c0 + side] = img
    A = np.array([[res, 0, 0], [0, -res, size_m[1]], [0, 0, 1]])
    Hm = K @ T[:3][:, [0, 1, 3]] @ A
    return cv2.warpPerspective(board, Hm, (640, 480), flags=cv2.INTER_LINEAR, borderValue=90), K, T


def test_board_size_is_measured_from_three_markers_and_the_pose_follows():
    img, K, T = _marker_image(hide=(0,))
    markers = detect_markers(make_detector(), img)
    assert sorted(markers) == [1, 2, 3]
    size, T_est, rms = measure_board(markers, K)
    assert size == pytest.approx((0.8, 0.6), abs=0.012) and rms < 1.0  # ~1 % large: ArUco corner bias
    assert np.linalg.norm(T_est[:3, 3] - T[:3, 3]) < 0.01
    T2, rms2 = solve_pose({i: markers[i] for i in (1, 2)}, (0.8, 0.6), K)
    assert np.linalg.norm(T2[:3, 3] - T[:3, 3]) < 0.02 and rms2 < 1.0
    with pytest.raises(ValueError, match="needs 3 markers"):
        measure_board({i: markers[i] for i in (1, 2)}, K)


# -- frames and params -----------------------------------------------------------------------------------

def test_frames_decode_every_encoding_and_name_what_is_wrong():
    rgb = (np.arange(48 * 64 * 3) % 251).astype(np.uint8).reshape(48, 64, 3)
    k = CameraIntrinsics(60.0, 60.0, 32.0, 24.0, 64, 48)
    pose = Pose([0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0])

    def msg(encoding, data, kk=k):
        return CameraFrame(seq=0, stamp_ns=0, camera="c", encoding=encoding, data=data, intrinsics=kk,
                           T_camera_to_world=pose)

    assert np.array_equal(rgb_from_message(msg("rgb8", rgb.tobytes())), rgb)
    assert np.array_equal(rgb_from_message(msg("bgr8", rgb[..., ::-1].tobytes())), rgb)
    png = cv2.imencode(".png", rgb[..., ::-1])[1].tobytes()
    assert np.array_equal(rgb_from_message(msg("png", png)), rgb)
    assert rgb_from_message(msg("mono8", rgb[..., 0].tobytes())).shape == (48, 64, 3)
    with pytest.raises(FrameError, match="corrupt png"):
        rgb_from_message(msg("png", png[:40]))
    with pytest.raises(FrameError, match="size mismatch"):
        rgb_from_message(msg("png", png, CameraIntrinsics(60.0, 60.0, 32.0, 24.0, 32, 24)))


@pytest.mark.parametrize("table,text", [
    ({"publish_rate_hz": 0.5}, r"publish_rate_hz must be a number in \[1.0, 200.0\]"),
    ({"source": "camera:0"}, "source must be 'zenoh'"),
    ({"ink": {"inks": {"white": [250, 250, 250]}}}, "inks.white .* must be darker than board_rgb"),
    ({"ink": {"illumination_range": [1.2, 1.5]}}, "illumination_range must be"),
    ({"board": {"size_m": [0.1, 0.1]}}, "size_m must be"),
    ({"board": {"min_markers": 0}}, "min_markers must be an integer"),
    ({"kappa": {"colour": 1}}, r"unknown key\(s\) \['colour'\]"),
])
def test_bad_params_name_the_key_and_its_range(table, text):
    with pytest.raises(ConfigError, match=text):
        PerceptionParams.from_table(table)


def test_source_specs():
    assert parse_source("zenoh") == ("zenoh", "")
    assert parse_source("folder:/x") == ("folder", "/x")
    assert parse_source("device:2") == ("device", "2")
    with pytest.raises(ConfigError):
        parse_source("device:cam")


def test_the_example_config_shows_the_defaults():
    import tomllib

    from .conftest import REPO

    with open(REPO / "config" / "example.toml", "rb") as f:
        table = tomllib.load(f)["perception"]
    assert PerceptionParams.from_table(table) == PerceptionParams()
