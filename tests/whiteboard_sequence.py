"""A wipe sequence made from a real photograph (tests/fixtures/whiteboards): before, during and after erasing.

No public set shows one board photographed before, during and after an
eraser, so the frames are edits of the real photograph, made with its own
pixels: a drawing is *erased* by filling the image area of its hand-made
mask (grown by 1 cm, so its strokes' blurred edges go too) from the board
around it (OpenCV's Telea inpainting), and a *ghost* of ``ghost`` times
the drawing's contrast is left in it, as a dry eraser leaves; *half
erased* does that to one half of the mask; *redrawn* is the photograph
again. Each frame is the edited image with fresh sensor noise
(Gaussian, sigma 2 grey levels) and JPEG-encoded at quality 90, as a
camera sends the same scene again and again.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from perception.check_board import check_board
from perception.params import PerceptionParams

#: An erased drawing's mask grows by this before filling [m].
ERASE_GROW_M = 0.01


def image_polygon(check, polygon_m: np.ndarray) -> np.ndarray:
    """(n, 2) float32 image points [px] of board-frame points ``polygon_m`` (n, 2) [m]."""
    P = check.K @ check.T_board_to_camera[:3][:, [0, 1, 3]]
    h = np.column_stack([polygon_m, np.ones(len(polygon_m))]) @ P.T
    return (h[:, :2] / h[:, 2:]).astype(np.float32)


class Eraser:
    """Edits of one photograph (BGR uint8) of a board whose drawings are ``stains`` (label, ink, polygon_m)."""

    def __init__(self, bgr: np.ndarray, params: PerceptionParams, stains: Sequence[Mapping[str, Any]]) -> None:
        self.bgr = bgr
        self.check = check_board(bgr, params)
        assert self.check.found, self.check.why
        self.stains = {s["label"]: np.asarray(s["polygon_m"], float) for s in stains}
        self._clean: dict[str, np.ndarray] = {}

    def _mask(self, label: str, half: bool = False) -> np.ndarray:
        poly = self.stains[label]
        centre = poly.mean(axis=0)
        grown = centre + (poly - centre) * (1.0 + 2 * ERASE_GROW_M / np.ptp(poly, axis=0).min())
        if half:  # the left half (board x) of the grown polygon
            cut = centre[0]
            grown = np.array([[min(x, cut), y] for x, y in grown])
        mask = np.zeros(self.bgr.shape[:2], np.uint8)
        cv2.fillPoly(mask, [np.round(image_polygon(self.check, grown)).astype(np.int32)], 255)
        return mask

    def erased(self, labels: Sequence[str], ghost: float = 0.1, half: Sequence[str] = ()) -> np.ndarray:
        """The photograph with ``labels`` erased to a ghost of ``ghost`` of their contrast (``half``: those of
        them erased on their left half only)."""
        out = self.bgr.astype(np.float32)
        for label in labels:
            mask = self._mask(label, half=label in half)
            clean = cv2.inpaint(self.bgr, mask, 7, cv2.INPAINT_TELEA).astype(np.float32)
            sel = mask > 0
            out[sel] = clean[sel] + ghost * (self.bgr.astype(np.float32)[sel] - clean[sel])
        return np.clip(out, 0, 255).astype(np.uint8)


def camera_frames(bgr: np.ndarray, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """``n`` frames of the scene ``bgr``: sensor noise, then JPEG (quality 90) and back, each time afresh."""
    out = []
    for _ in range(n):
        noisy = np.clip(bgr.astype(np.float32) + rng.normal(0.0, 2.0, bgr.shape), 0, 255).astype(np.uint8)
        ok, data = cv2.imencode(".jpg", noisy, [cv2.IMWRITE_JPEG_QUALITY, 90])
        out.append(cv2.imdecode(data, cv2.IMREAD_COLOR))
    return out
