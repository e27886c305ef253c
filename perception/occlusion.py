"""The occlusion mask's morphology, done where the occluded pixels are: the same masks as on the whole image.

A board image is mostly board: what is not (the arm, glare, a stroke's
colour fringe) covers a small share of it. :mod:`perception.classify`
opens the not-board pixels (specks go), closes them together with the
border that is never judged (the board's edges and markers, the same every
frame) and grows them. On the whole image each of these costs a pass of a
large kernel over every pixel (a 21 x 21 disc for a 4 cm fill at 2 mm);
here each works on the bounding box of the not-board pixels grown by the
reach of its kernel, and the border's own closing is computed once:

- opening ``B``: an eroded pixel lies in B's box, its dilation within one
  kernel radius ``r`` of it; a box of B grown by ``r`` holds both (the
  erosion treats pixels past the box as set, but every box pixel within
  ``r`` of the box's edge is clear, so nothing past it is read as set);
- closing ``B | N`` (``N`` the border, fixed): ``dilate(B | N) = dilate(B) |
  dilate(N)`` with ``dilate(N)`` kept; the erosion of that differs from the
  kept ``close(N)`` only within ``2 r`` of B's box (a pixel whose disc
  reaches ``dilate(B)``), and reads ``r`` beyond: a box of B grown by
  ``3 r`` is enough, and outside ``2 r`` the result is ``close(N)``.
"""

from __future__ import annotations

import cv2
import numpy as np


def _grown_box(mask: np.ndarray, pad: int) -> tuple[int, int, int, int] | None:
    """``(r0, r1, c0, c1)``: the bounding box of the set pixels of ``mask`` (rows, cols) uint8 grown by ``pad``
    and clipped to the image, or None when none is set."""
    x, y, w, h = cv2.boundingRect(mask)
    if w == 0:
        return None
    rows, cols = mask.shape
    return max(y - pad, 0), min(y + h + pad, rows), max(x - pad, 0), min(x + w + pad, cols)


def open_local(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``cv2.morphologyEx(mask, MORPH_OPEN, kernel)`` of ``mask`` (rows, cols) uint8, computed on the set
    pixels' box (module docstring); a new array."""
    out = np.zeros_like(mask)
    box = _grown_box(mask, max(kernel.shape) // 2)
    if box is not None:
        r0, r1, c0, c1 = box
        out[r0:r1, c0:c1] = cv2.morphologyEx(mask[r0:r1, c0:c1], cv2.MORPH_OPEN, kernel)
    return out


class BorderClosing:
    """Closing of ``B | N`` for a fixed ``N`` (the border never judged) and a changing ``B`` (module docstring).

    border : (rows, cols) bool, ``N``. kernel : the closing's structuring element (odd square, centred).
    """

    def __init__(self, border: np.ndarray, kernel: np.ndarray) -> None:
        self.kernel = kernel
        self.r = max(kernel.shape) // 2
        n = border.view(np.uint8)
        self._dilated_border = cv2.dilate(n, kernel)
        self._closed_border = cv2.morphologyEx(n, cv2.MORPH_CLOSE, kernel)

    def close(self, mask: np.ndarray) -> np.ndarray:
        """``cv2.morphologyEx(mask | border, MORPH_CLOSE, kernel)`` of ``mask`` (rows, cols) uint8: a new uint8
        array."""
        out = self._closed_border.copy()
        box = _grown_box(mask, 3 * self.r)
        if box is None:
            return out
        r0, r1, c0, c1 = box
        dilated: np.ndarray = cv2.dilate(mask[r0:r1, c0:c1], self.kernel)
        grown = dilated | self._dilated_border[r0:r1, c0:c1]
        closed = cv2.erode(grown, self.kernel)
        inner = _grown_box(mask, 2 * self.r)
        assert inner is not None  # the mask has set pixels (box above)
        i0, i1, j0, j1 = inner
        out[i0:i1, j0:j1] = closed[i0 - r0:i1 - r0, j0 - c0:j1 - c0]
        return out
