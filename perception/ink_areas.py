"""The areas a robot must wipe, each with its ink, from one frame's classification; and how well they match masks.

A drawing (a word, a box around a formula) is many strokes. Its *area* is
one cluster of stain pixels (:func:`~perception.cluster.cluster_pixels`,
link distance ``link_m``, clusters under ``min_area_m2`` of ink dropped)
and its convex hull: the region that holds the drawing, as a person would
outline it. Each stroke (8-connected stain pixels) takes the ink with
the most ink fraction over it (:func:`stroke_inks`: a stroke is one
marker), a minor ink within a drawing takes the drawing's main ink
(:func:`drawing_inks`), then each ink is clustered on its own: two
drawings of different inks are two areas however close.

:func:`compare` scores areas per ink against hand-made masks: IoU, and the
false stain area (stain pixels outside every mask) as a fraction of the
clean board. Pure numpy/OpenCV on the rectified grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import find_objects

from .classify import InkMap
from .cluster import cluster_pixels, disc
from .rectify import BoardGrid

#: An ink with less than this share of a drawing's stain pixels is taken for the drawing's main ink.
MINOR_INK_SHARE = 0.15


@dataclass(frozen=True)
class InkArea:
    """One drawing: ``ink`` (name), ``mask`` (rows, cols) bool its filled area, ``ink_px`` its stain pixels."""

    ink: str
    mask: np.ndarray
    ink_px: int


def stroke_inks(ink: InkMap) -> np.ndarray:
    """(rows, cols) uint8, 0 off the stain pixels: each stain pixel's ink made that of its stroke (8-connected
    stain pixels), the ink with the largest summed ink fraction over it; a stroke is one marker, its faint or
    mixed edge pixels are not another ink."""
    if ink.ink is None or len(ink.names) == 1:
        return np.zeros(ink.stain.shape, np.uint8)
    n, labels = cv2.connectedComponents(ink.stain.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    k = len(ink.names)
    on = ink.stain
    lab = labels[on]
    weights = np.bincount(lab * k + ink.ink[on], weights=ink.d[on], minlength=n * k).reshape(n, k)
    out = np.zeros(on.shape, np.uint8)  # (off the stain pixels: 0)
    out[on] = weights.argmax(axis=1).astype(np.uint8)[lab]
    return out


def drawing_inks(ink: InkMap, link_px: float) -> np.ndarray:
    """(rows, cols) uint8: :func:`stroke_inks`, then within each drawing (stain pixels of any ink clustered at
    ``link_px``) the pixels of an ink with under :data:`MINOR_INK_SHARE` of the drawing's pixels that lie within
    the outline (convex hull) of the drawing's main ink take the main ink: a letter of a blue word read as black,
    a stretch of a purple box read as brown, are colour noise, not drawings of their own; a faint drawing next to
    a strong one (outside its outline) keeps its ink."""
    strokes = stroke_inks(ink)
    n, labels = cluster_pixels(ink.stain, link_px)
    if n == 0:
        return strokes
    k = len(ink.names)
    on = ink.stain
    counts = np.bincount(labels[on] * k + strokes[on], minlength=(n + 1) * k).reshape(n + 1, k)
    main = counts.argmax(axis=1)
    minor = (counts > 0) & (counts < MINOR_INK_SHARE * counts.sum(axis=1, keepdims=True))
    with_minor = np.flatnonzero(minor[1:].any(axis=1)) + 1
    boxes = find_objects(labels) if with_minor.size else []  # each drawing's box (one pass): the work is done there
    for c in with_minor:
        lab, st = labels[boxes[c - 1]], strokes[boxes[c - 1]]
        drawing = lab == c
        inside = hull(drawing & (st == main[c]))
        move = drawing & inside & minor[c][st]
        st[move] = main[c]
    return strokes


def hull(mask: np.ndarray) -> np.ndarray:
    """(rows, cols) bool: the convex hull of the True pixels of ``mask``."""
    pts = cv2.findNonZero(mask.view(np.uint8))
    out = np.zeros(mask.shape, np.uint8)
    cv2.fillConvexPoly(out, cv2.convexHull(pts), 1)
    return out.view(bool)


def ink_areas(ink: InkMap, resolution_m: float, link_m: float, min_area_m2: float) -> list[InkArea]:
    """The drawings on the board in ``ink``, largest first (module docstring); each ink clustered on its own,
    so two drawings of different inks are two areas however close."""
    link_px = link_m / resolution_m
    min_px = max(int(np.ceil(min_area_m2 / resolution_m ** 2)), 1)
    strokes = None if ink.ink is None or len(ink.names) == 1 else drawing_inks(ink, link_px)
    out = []
    for k, name in enumerate(ink.names):
        pixels = ink.stain if strokes is None else ink.stain & (strokes == k)
        n, labels = cluster_pixels(pixels, link_px)
        if n == 0:
            continue
        counts = np.bincount(labels.ravel(), minlength=n + 1)
        for j in np.flatnonzero(counts >= min_px):
            if j:
                out.append(InkArea(name, hull(labels == j), int(counts[j])))
    out.sort(key=lambda a: -a.ink_px)
    return out


def polygon_mask(grid: BoardGrid, polygon_m: np.ndarray) -> np.ndarray:
    """(rows, cols) bool: grid pixels whose centre lies in ``polygon_m`` (n, 2), board frame [m]."""
    r = grid.resolution_m
    rows = grid.shape[0]
    pts = np.column_stack([np.asarray(polygon_m)[:, 0] / r - 0.5, rows - np.asarray(polygon_m)[:, 1] / r - 0.5])
    out = np.zeros(grid.shape, np.uint8)
    cv2.fillPoly(out, [np.round(pts * 16).astype(np.int32)], 1, lineType=cv2.LINE_8, shift=4)
    return out.view(bool)


@dataclass(frozen=True)
class InkScore:
    """One ink in one image: IoU of the areas against the masks (over visible pixels), their visible pixel
    counts, and the share of the masks perception saw (not occluded)."""

    ink: str
    iou: float
    found_px: int
    truth_px: int
    seen: float


def compare(areas: list[InkArea], truth: dict[str, np.ndarray], stain: np.ndarray,
            visible: np.ndarray, looked_at: np.ndarray, tolerance_px: int = 0) -> tuple[list[InkScore], float]:
    """Per ink of ``truth`` (name -> (rows, cols) bool mask), the IoU of the areas of that ink over the
    ``visible`` pixels (what perception says it could not see is not scored, and said: ``InkScore.seen``); and
    the false stain area: ``stain`` pixels farther than ``tolerance_px`` from every mask (a hand-drawn outline's
    precision) over the clean board (``looked_at`` minus the masks)."""
    scores = []
    for name, want in truth.items():
        got = np.zeros(want.shape, bool)
        for a in areas:
            if a.ink == name:
                got |= a.mask
        seen = int(np.count_nonzero(want & visible)) / max(int(np.count_nonzero(want & looked_at)), 1)
        got &= visible
        want = want & visible
        union = int(np.count_nonzero(got | want))
        scores.append(InkScore(name, int(np.count_nonzero(got & want)) / union if union else 1.0,
                               int(got.sum()), int(want.sum()), seen))
    anywhere = np.zeros(stain.shape, bool)
    for want in truth.values():
        anywhere |= want
    clean = looked_at & ~anywhere
    if tolerance_px > 0:
        anywhere = cv2.dilate(anywhere.view(np.uint8), disc(tolerance_px)).view(bool)
    false = int(np.count_nonzero(stain & looked_at & ~anywhere)) / max(int(clean.sum()), 1)
    return scores, false
