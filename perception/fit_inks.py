"""``lamps perception --fit-inks``: each ink's colour fitted from photographs of the board with labelled drawings.

The palette (``[perception.ink] inks``) is each marker's colour on the
clean board ``board_rgb`` in the same light. Measured here from real
photographs: each photograph is rectified (its markers, ``[perception.board]``)
and divided by its local white (:class:`~perception.classify.InkClassifier`:
so the room's light and the camera's white balance drop out), and within
each labelled drawing (a polygon in the board frame and the ink a person
names, the format of ``tests/fixtures/whiteboards/stains.toml``) the
darkest :data:`STROKE_SHARE` of the pixels are its strokes. An ink's
absorption ``a = 1 - ink / board`` has the direction of the median stroke
``1 - x`` over all its drawings and photographs, and the length of their
99th percentile along it: the full ink is the darkest the camera saw of it.
Pixels the sensor clipped are left out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from .check_board import check_board
from .classify import SATURATED, InkClassifier, fit_white
from .params import PerceptionParams
from .photo_score import truth_masks
from .rectify import BoardGrid

#: The darkest share of a drawing's pixels taken as its strokes.
STROKE_SHARE = 0.04


def stroke_absorptions(bgr: np.ndarray, params: PerceptionParams,
                       stains: Sequence[Mapping[str, Any]]) -> dict[str, np.ndarray]:
    """Ink name -> (n, 3) ``1 - x`` of the stroke pixels of its drawings in one photograph (x relative to the
    local white). Raises ValueError when the board is not found."""
    check = check_board(bgr, params)
    if not check.found or check.size_m is None or check.T_board_to_camera is None:
        raise ValueError(f"board not found: {check.why}")
    grid = BoardGrid(check.size_m, params.board.resolution_m)
    rect = grid.warp(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), grid.image_from_grid(check.K, check.T_board_to_camera))
    looked_at = grid.looked_at(params.board.edge_margin_m, params.board.marker_margin_m, params.board.layout)
    clf = InkClassifier(params.ink, looked_at, params.board.resolution_m)
    rgb = rect.astype(np.float32)
    white_g = np.maximum(cv2.transform(clf._affine_basis, fit_white(rgb, looked_at, clf.block_px).astype(np.float32)),
                         1.0)
    white, _ = clf.local_white(rgb, white_g)
    y = 1.0 - rgb / np.maximum(white, 1.0)
    unclipped = (rect < SATURATED).all(axis=2) & looked_at
    out: dict[str, list[np.ndarray]] = {}
    for s in stains:
        mask = truth_masks(grid, [s])[s["ink"]] & unclipped
        if mask.sum() < 50:
            continue
        ys = y[mask]
        dark = ys.mean(axis=1) >= np.quantile(ys.mean(axis=1), 1.0 - STROKE_SHARE)
        out.setdefault(s["ink"], []).append(ys[dark])
    return {k: np.concatenate(v) for k, v in out.items()}


def fit_palette(samples: Sequence[dict[str, np.ndarray]], board_rgb: tuple[float, float, float]
                ) -> dict[str, tuple[float, float, float]]:
    """Ink name -> its colour on ``board_rgb`` from the stroke samples of several photographs (module docstring)."""
    inks: dict[str, list[np.ndarray]] = {}
    for sample in samples:
        for name, ys in sample.items():
            inks.setdefault(name, []).append(ys)
    out = {}
    for name, parts in inks.items():
        ys = np.concatenate(parts)
        direction = np.median(ys, axis=0)
        direction /= max(float(np.linalg.norm(direction)), 1e-9)
        length = float(np.quantile(ys @ direction, 0.99))
        a = np.clip(direction * length, 0.0, 1.0)
        r, g, b = (float(round(v, 1)) for v in np.clip(np.array(board_rgb) * (1.0 - a), 0.0, 255.0))
        out[name] = (r, g, b)
    return out


def toml_line(palette: Mapping[str, tuple[float, float, float]]) -> str:
    """``inks = { ... }`` for ``[perception.ink]``."""
    return "inks = { " + ", ".join(f"{k} = [{r:.0f}, {g:.0f}, {b:.0f}]" for k, (r, g, b) in palette.items()) + " }"


def main_fit_inks(images: Sequence[str], masks: str, params: PerceptionParams) -> int:
    """The ``--fit-inks`` command: print the fitted palette as a TOML line; exit 1 naming a bad input."""
    import sys
    import tomllib
    from pathlib import Path

    try:
        labels = tomllib.loads(Path(masks).read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        print(f"lamps perception: error: --masks {masks}: {exc}", file=sys.stderr)
        return 1
    samples = []
    for image in images:
        name = Path(image).stem
        bgr = cv2.imread(image, cv2.IMREAD_COLOR)
        if bgr is None:
            print(f"lamps perception: error: --fit-inks {image}: not an image OpenCV can read", file=sys.stderr)
            return 1
        if name not in labels or not labels[name].get("stains"):
            print(f"lamps perception: error: --masks {masks} has no [{name}] stains for {image}", file=sys.stderr)
            return 1
        try:
            samples.append(stroke_absorptions(bgr, params, labels[name]["stains"]))
        except (ValueError, KeyError, TypeError) as exc:
            print(f"lamps perception: error: {image}: {exc}", file=sys.stderr)
            return 1
        print(f"{image}: " + ", ".join(f"{k} {len(v)} stroke pixels" for k, v in samples[-1].items()))
    print(toml_line(fit_palette(samples, params.ink.board_rgb)))
    return 0
