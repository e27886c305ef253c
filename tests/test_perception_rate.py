"""Perception at a camera's rate gives what the plain array formulation gives: the compiled unmixing, the
morphology on the occluded pixels' box, clustering on the ink's box, markers looked for where they were."""

from __future__ import annotations

import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from perception.board import BoardTracker, detect_markers
from perception.classify import D_RANGE, SATURATED, InkClassifier, fit_white
from perception.cluster import cluster_pixels, disc
from perception.occlusion import BorderClosing, open_local
from perception.params import InkParams, PerceptionParams
from perception.sources import camera_model

PHOTOS = Path(__file__).parent / "fixtures" / "whiteboards"
REAL = tomllib.loads((PHOTOS / "board.toml").read_text())["perception"]


def reference_unmix(clf: InkClassifier, rect: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(d, ink, bad)`` of the colour model as whole-image array operations (float64), the formulation the
    compiled pass replaces (perception/classify.py's module docstring)."""
    p = clf.p
    rgb = rect.astype(np.float64)
    coef = fit_white(rect.astype(np.float32), clf.looked_at, clf.block_px).astype(np.float32).astype(np.float64)
    rows, cols = clf.looked_at.shape
    basis = np.dstack([np.ones((rows, cols)), np.tile(np.arange(cols), (rows, 1)),
                       np.tile(np.arange(rows)[:, None], (1, cols))])
    white = np.maximum(basis @ coef.T, 1.0)
    if clf._cell:
        local, edges = clf._local_unkept(rect.astype(np.float32))
        lo, hi = p.white_follow
        local = np.minimum(np.maximum(local, white * lo), white * hi)
        x = 1.0 - (local - rgb) / np.minimum(local, white)
    else:
        x, edges = rgb / white, None
    xh = np.concatenate([x, np.ones((rows, cols, 1))], axis=2)
    st = np.einsum("kij,rcj->krci", clf._to_st.astype(np.float64), xh)  # (k, rows, cols, 2)
    e = np.einsum("kij,rcj->krci", clf._to_residual.astype(np.float64), xh)
    res2 = (e ** 2).sum(axis=3)
    k = res2.argmin(axis=0)
    s = np.take_along_axis(st[..., 0], k[None], 0)[0]
    t = np.take_along_axis(st[..., 1], k[None], 0)[0]
    best = np.take_along_axis(res2, k[None], 0)[0]
    d = np.where(s != 0, t / np.where(s != 0, s, 1.0), 0.0)
    tol = p.max_residual + p.chroma_tolerance * np.clip(d, 0.0, 1.0)
    lo, hi = p.illumination_range
    bad = ~((s >= lo) & (s <= hi) & (d >= D_RANGE[0]) & (d <= D_RANGE[1]) & (best <= tol * tol))
    if edges is not None:
        bad |= edges | (rect >= SATURATED).any(axis=2)
    return d, k, bad


@pytest.mark.parametrize("profile", ["simulator", "real board"])
def test_the_compiled_unmixing_is_the_array_formulation(profile):
    rng = np.random.default_rng(3)
    params = InkParams() if profile == "simulator" else PerceptionParams.from_table(REAL).ink
    rows, cols = 90, 120
    clf = InkClassifier(params, np.ones((rows, cols), bool), 0.002)
    # a board under a light gradient with strokes of every ink, shading, glare and an arm-like grey patch
    board = np.array(params.board_rgb) * np.linspace(0.8, 1.05, cols)[None, :, None] * np.ones((rows, 1, 1))
    img = board.copy()
    for i, ink in enumerate(params.inks.values()):
        frac = rng.uniform(0.1, 1.0)
        img[10 + 12 * i:16 + 12 * i, 10:100] = (1 - frac) * board[0, 0] + frac * np.array(ink)
    img[70:85, 20:40] = (91, 91, 94)
    img[5:12, 100:115] = 255
    img = np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8)
    d8 = np.empty((rows, cols), np.float32)
    ink8 = np.empty((rows, cols), np.uint8)
    bad8 = np.empty((rows, cols), np.uint8)
    from perception.unmix import unmix_into

    coef = fit_white(img.astype(np.float32), clf.looked_at, clf.block_px).astype(np.float32)
    local, edges = clf._local_unkept(img.astype(np.float32)) if clf._cell else (clf._no_local, clf._no_edges)
    unmix_into(img, coef, local, clf._follow, edges, clf._to_st, clf._to_residual, clf._limits, SATURATED,
               d8, ink8, bad8)
    d, k, bad = reference_unmix(clf, img)
    assert np.abs(d8 - d).max() < 1e-3
    # where two inks fit within float32 rounding of each other the pick may differ: nowhere here
    assert (ink8 == k).mean() > 0.999
    assert (bad8.view(bool) != bad).sum() <= 2  # a pixel exactly at a limit may fall either side in float32
    assert bad.any() and (~bad).any() and len(np.unique(k[~bad & (d > 0.3)])) >= min(2, len(params.inks))


@pytest.mark.parametrize("seed", range(4))
def test_the_occlusion_morphology_on_its_box_is_the_whole_image_one(seed):
    rng = np.random.default_rng(seed)
    rows, cols = 150, 200
    mask = np.zeros((rows, cols), np.uint8)
    for _ in range(rng.integers(0, 5)):
        r, c = rng.integers(0, rows), rng.integers(0, cols)
        mask[r:r + rng.integers(1, 30), c:c + rng.integers(1, 30)] = 1
    mask |= (rng.random((rows, cols)) < 0.002).astype(np.uint8)
    border = np.zeros((rows, cols), bool)
    border[:, :3] = border[:, -3:] = border[:3] = border[-3:] = True
    border[40:55, 60:75] = True  # a marker
    speck = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
    fill = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (21, 21))
    assert np.array_equal(open_local(mask, speck), cv2.morphologyEx(mask, cv2.MORPH_OPEN, speck))
    want = cv2.morphologyEx(mask | border.view(np.uint8), cv2.MORPH_CLOSE, fill)
    assert np.array_equal(BorderClosing(border, fill).close(mask), want)
    assert np.array_equal(BorderClosing(border, fill).close(np.zeros_like(mask)),
                          cv2.morphologyEx(border.view(np.uint8), cv2.MORPH_CLOSE, fill))


@pytest.mark.parametrize("seed", range(3))
def test_clustering_on_the_box_numbers_as_on_the_whole_image(seed):
    rng = np.random.default_rng(seed)
    mask = np.zeros((120, 160), bool)
    mask[30:90, 40:130] = rng.random((60, 90)) < 0.02
    eps = 6.5
    comp = cv2.connectedComponents(cv2.dilate(mask.view(np.uint8), disc(eps / 2)), connectivity=8,
                                   ltype=cv2.CV_32S)[1]
    labels = np.where(mask, comp, 0)
    used = np.unique(labels[labels > 0])
    lut = np.zeros(comp.max() + 1, np.int32)
    lut[used] = np.arange(1, used.size + 1)
    n, ours = cluster_pixels(mask, eps)
    assert n == used.size and np.array_equal(ours, lut[labels])
    assert cluster_pixels(np.zeros((5, 5), bool), eps)[0] == 0


def test_markers_looked_for_where_they_were_are_where_the_whole_image_finds_them():
    params = PerceptionParams.from_table(REAL)
    bgr = cv2.imread(str(PHOTOS / "sideangle.jpg"))
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    K, T = camera_model(params.model, grey.shape[1], grey.shape[0])
    tracker = BoardTracker(params.board)
    assert tracker.update(grey, K, T, 0.0) is not None and len(tracker._corners) == 4
    whole = detect_markers(tracker.detector, grey, tracker.layout.ids)
    windowed = tracker._detect(grey)
    assert sorted(windowed) == sorted(whole)
    assert max(np.abs(windowed[i] - whole[i]).max() for i in whole) < 0.01
    # the camera moved by 70 px: no marker is in its window any more, the whole image is searched
    shifted = np.roll(grey, 70, axis=0)
    moved = tracker._detect(shifted)
    assert sorted(moved) == sorted(whole)
    assert max(np.abs(moved[i] - whole[i] - [0, 70]).max() for i in whole) < 0.01


def test_a_stains_region_grown_piece_by_piece_is_the_one_made_at_once():
    """Cores grow by a few pixels a frame (noise at a stroke's edge): region, reach and near, grown by the new
    pixels only, equal those made from the whole core."""
    import copy

    from perception.classify import InkMap
    from perception.params import KappaParams, StainParams
    from perception.rectify import BoardGrid
    from perception.tracking import StainTracker

    rng = np.random.default_rng(5)
    grid = BoardGrid((0.4, 0.3), 0.002)
    rows, cols = grid.shape
    tracker = StainTracker(grid, StainParams(confirm_s=0.1), KappaParams(), 0.3, 0.05)
    base = np.zeros((rows, cols), np.float32)
    base[40:60, 40:90] = 0.8
    base[90:110, 120:150] = 0.7
    checked = 0
    for n in range(12):
        grow = cv2.dilate((base > 0).view(np.uint8), np.ones((3, 3), np.uint8), iterations=1 + n // 3).view(bool)
        d = np.where(grow & (rng.random((rows, cols)) < 0.35 + 0.05 * n), 0.6, base).astype(np.float32)
        looked = np.ones((rows, cols), bool)
        tracker.update(InkMap(d, np.zeros((rows, cols), bool), d >= 0.3, looked), 0.1 * n)
        for tr in tracker.tracks:
            fresh = copy.deepcopy(tr)
            tracker._set_region(fresh)
            assert fresh.box == tr.box
            assert np.array_equal(fresh.region, tr.region)
            assert np.array_equal(fresh.reach, tr.reach) and np.array_equal(fresh.near, tr.near)
            checked += 1
    assert checked >= 10 and len(tracker.tracks) == 2


def test_the_status_says_the_frame_to_stains_latency(tmp_path):
    """An offline source stamps each frame when it reads it: the status carries the p50 and p99 from there to
    the stains message (the real camera's path: read, decode, process, publish)."""
    import shutil

    from perception.service import PerceptionService
    from perception.sources import OpenCVSource

    for i in range(8):
        shutil.copy(PHOTOS / "straight.jpg", tmp_path / f"{i:02d}.jpg")
    params = PerceptionParams.from_table({**REAL, "source": f"folder:{tmp_path}"})
    sent = []
    service = PerceptionService(params, None, OpenCVSource(params.source, params), sink=sent.append)
    assert service.run() == 8 and len(sent) >= 4
    counters = service.status().counters
    p50, p99 = counters["frame_to_stains_p50_us"], counters["frame_to_stains_p99_us"]
    assert 0 < p50 <= p99 < 5_000_000
    assert p50 >= counters["process_p50_us"] * 0.5  # it holds the processing
