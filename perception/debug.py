"""Debug images: the rectified board with what perception made of it (occlusion, stains, ids, kappa)."""

from __future__ import annotations

import cv2
import numpy as np

#: Drawing colours (RGB): occlusion tint, open stain, wiped stain (kappa = 1).
OCCLUDED_RGB = np.array([230, 40, 40], np.float32)
OPEN_RGB = (255, 140, 0)
DONE_RGB = (0, 170, 0)


def debug_image(result, perception) -> np.ndarray:
    """(rows, cols, 3) uint8 RGB: the rectified board, occluded pixels tinted, each stain outlined and labelled."""
    img = result.rect.copy()
    occ = result.ink.occluded
    img[occ] = (0.5 * img[occ] + 0.5 * OCCLUDED_RGB).astype(np.uint8)
    tracker = perception.tracker
    for tr in tracker.tracks:
        colour = DONE_RGB if tr.kappa else OPEN_RGB
        contours, _ = cv2.findContours(tr.region.view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(img, contours, -1, colour, 1)
        r0, _, c0, _ = tr.box
        cv2.putText(img, f"{tr.id} {tr.remaining:.0%} v{tr.visible:.0%}", (c0, max(r0 - 3, 10)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1, cv2.LINE_AA)
    return img


def debug_jpeg(result, perception, quality: int = 80) -> tuple[bytes, tuple[int, int]]:
    """The :func:`debug_image` as JPEG bytes and its (rows, cols)."""
    img = debug_image(result, perception)
    ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("JPEG encoding of the debug image failed")
    return buf.tobytes(), img.shape[:2]
