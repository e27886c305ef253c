"""Perception on one photograph against hand-made stain masks: per ink IoU, false stain area, what was not seen.

The masks are polygons in the board frame, one per drawing, with the ink a
person names (``tests/fixtures/whiteboards/stains.toml`` is the format).
The photograph goes through what :class:`~perception.pipeline.Perception`
does to a frame (markers, pose, rectification, classification) and the
drawings through :func:`~perception.ink_areas.ink_areas`; scores are
:func:`~perception.ink_areas.compare`'s. Used by the tests and by
``scripts/ink_table.py``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from .check_board import check_board
from .classify import InkClassifier, InkMap
from .ink_areas import InkArea, InkScore, compare, ink_areas, polygon_mask
from .params import PerceptionParams
from .rectify import BoardGrid

#: Stain pixels this close to a hand-drawn outline are not false: the outline's own precision [m].
OUTLINE_TOLERANCE_M = 0.01


@dataclass
class PhotoScore:
    """One photograph: per ink scores, the false stain area and the occluded share of the clean board
    (fractions), the board's size [m], and the rectified image, classification and areas (for drawing)."""

    scores: list[InkScore]
    false_area: float
    occluded: float
    size_m: tuple[float, float]
    rect: np.ndarray
    ink: InkMap
    areas: list[InkArea]
    truth: dict[str, np.ndarray]


def truth_masks(grid: BoardGrid, stains: Sequence[Mapping[str, Any]]) -> dict[str, np.ndarray]:
    """Ink name -> (rows, cols) bool union of the polygons (``polygon_m`` (n, 2) [m]) of that ink."""
    out: dict[str, np.ndarray] = {}
    for s in stains:
        polygon = np.asarray(s["polygon_m"], float)
        if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3:
            raise ValueError(f"stain {s.get('label', '?')!r}: polygon_m must be 3 or more [x, y] points")
        m = polygon_mask(grid, polygon)
        out[s["ink"]] = out.get(s["ink"], np.zeros(grid.shape, bool)) | m
    return out


def score_photo(bgr: np.ndarray, params: PerceptionParams, stains: Sequence[Mapping[str, Any]]) -> PhotoScore:
    """Score perception on ``bgr`` (H, W, 3) uint8 against ``stains`` (dicts with ``ink`` and ``polygon_m``).

    Raises ValueError when the board is not found (the photograph says why)."""
    check = check_board(bgr, params)
    if not check.found or check.size_m is None or check.T_board_to_camera is None:
        raise ValueError(f"board not found: {check.why}")
    grid = BoardGrid(check.size_m, params.board.resolution_m)
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    rect = grid.warp(rgb, grid.image_from_grid(check.K, check.T_board_to_camera))
    looked_at = grid.looked_at(params.board.edge_margin_m, params.board.marker_margin_m, params.board.layout)
    ink = InkClassifier(params.ink, looked_at, params.board.resolution_m).classify(rect)
    areas = ink_areas(ink, params.board.resolution_m, params.stains.link_m, params.stains.min_area_m2)
    truth = truth_masks(grid, stains)
    tol = int(round(OUTLINE_TOLERANCE_M / params.board.resolution_m))
    scores, false = compare(areas, truth, ink.stain, ink.visible, looked_at, tol)
    clean = looked_at.copy()
    for m in truth.values():
        clean &= ~m
    occluded = float(np.count_nonzero(ink.occluded & clean)) / max(int(clean.sum()), 1)
    return PhotoScore(scores, false, occluded, check.size_m, rect, ink, areas, truth)


def draw(score: PhotoScore) -> np.ndarray:
    """(rows, cols, 3) uint8 BGR: the rectified photograph faded, masks outlined red, found areas blue with their
    ink, false stain pixels magenta, occluded pixels yellow."""
    vis = (score.rect.astype(np.float32) * 0.5 + 120).astype(np.uint8)
    anywhere = np.zeros(score.ink.stain.shape, bool)
    for m in score.truth.values():
        anywhere |= m
    vis[score.ink.occluded] = (230, 220, 60)
    vis[score.ink.stain & ~anywhere] = (255, 0, 255)
    for m in score.truth.values():
        contours, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(vis, contours, -1, (220, 0, 0), 1)
    for a in score.areas:
        contours, _ = cv2.findContours(a.mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(vis, contours, -1, (0, 0, 220), 1)
        x, y, _, _ = cv2.boundingRect(contours[0])
        cv2.putText(vis, a.ink, (x + 2, y + 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 160), 1)
    return cv2.cvtColor(vis, cv2.COLOR_RGB2BGR)
