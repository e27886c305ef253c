"""Board pixels as clean board, stain, or occluded, in a colour model of marker ink on a white board.

A board pixel's colour ``I`` (3,), divided by the local white ``W`` (3,)
(the clean board under this frame's light), is modelled as::

    x = I / W = s (1 - d a),        a = 1 - ink_rgb / board_rgb

with ``s`` the illumination relative to ``W`` (shading, a soft shadow) and
``d`` the ink fraction (0 clean, 1 full ink). With ``t = s d`` the model is
linear, ``x = s 1 - t a``; ``(s, t)`` come per pixel from a least-squares
fit with a weak prior ``s ~ 1`` (weight ``prior_weight``, which decides
between shade and ink when the ink is neutral, e.g. black)::

    [s, t] = (A^T A + lambda e1 e1^T)^-1 (A^T x + lambda e1),   A = [1 | -a]  (3, 2)

A pixel is *occluded* (the arm, the eraser, a deep shadow, anything that is
not board) when ``s`` is outside ``illumination_range``, when the colour is
farther than ``max_residual`` from the model, when it lies outside the
camera image, or when the caller knows it hidden (the robot's own tool,
whose colour may be the ink's: :mod:`perception.self_filter`); occluded areas are closed over gaps narrower than
``occlusion_fill_m`` (highlights on the arm that look like white board)
and grow by ``occlusion_margin_m`` to catch mixed pixels at their edges. Otherwise it is *stain* when ``d >= stain_level``,
else *clean*. The threshold is on the ink fraction relative to the local
white, so it adapts to the light; no grey level is fixed.

``W`` is an affine function of the board coordinates per channel (a light
gradient across the board), fitted each frame to the brightest blocks of
the rectified image and refitted without the blocks far below the first fit
(the arm, big shadows).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .params import InkParams

#: Side of the blocks the white is measured on [m].
WHITE_BLOCK_M = 0.05
#: Ink fractions outside this are not ink on a board.
D_RANGE = (-0.3, 1.6)


@dataclass
class InkMap:
    """One frame's classification of the rectified board image, all (rows, cols).

    d : float32 ink fraction (0 where not judged). occluded : bool, not
    board or not seen. stain : bool, board with ``d >= stain_level``.
    looked_at : bool, pixels judged at all (board minus edges and markers).
    """

    d: np.ndarray
    occluded: np.ndarray
    stain: np.ndarray
    looked_at: np.ndarray

    @property
    def visible(self) -> np.ndarray:
        return self.looked_at & ~self.occluded


def ink_absorption(params: InkParams) -> np.ndarray:
    """(3,) absorption ``a = 1 - ink / board`` per RGB channel."""
    return 1.0 - np.array(params.ink_rgb) / np.array(params.board_rgb)


def unmixing_matrix(a: np.ndarray, prior_weight: float) -> tuple[np.ndarray, np.ndarray]:
    """``(M (2, 3), m (2,))`` with ``[s, t] = M x + m`` the regularised least-squares fit of ``x = s 1 - t a``."""
    A = np.column_stack([np.ones(3), -a])
    N = A.T @ A + np.diag([prior_weight, 0.0])
    Ninv = np.linalg.inv(N)
    return Ninv @ A.T, Ninv @ np.array([prior_weight, 0.0])


def fit_white(rgb: np.ndarray, looked_at: np.ndarray, block_px: int) -> np.ndarray:
    """(3, 3) coefficients ``W_c(col, row) = c0 + c1 col + c2 row`` of the local white per channel.

    rgb : (rows, cols, 3) float32. The white of a block is its brightest
    quarter-block average; blocks below 80 % of the brightest tenth are
    ignored, then those more than 8 % below the first fit.
    """
    rows, cols = looked_at.shape
    q = max(block_px // 4, 1)
    small = cv2.resize(rgb, (max(cols // q, 1), max(rows // q, 1)), interpolation=cv2.INTER_AREA)
    ok = cv2.resize(looked_at.astype(np.float32), (small.shape[1], small.shape[0]), interpolation=cv2.INTER_AREA) > 0.99
    lum = np.where(ok, small.mean(axis=2), 0.0)
    br, bc = small.shape[0] // 4, small.shape[1] // 4
    if br == 0 or bc == 0:
        return np.array([[float(np.max(small[..., c])), 0.0, 0.0] for c in range(3)])
    blocks = lum[:br * 4, :bc * 4].reshape(br, 4, bc, 4).transpose(0, 2, 1, 3).reshape(br, bc, 16)
    best = blocks.argmax(axis=2)
    bi, bj = np.divmod(best, 4)
    ii = np.arange(br)[:, None] * 4 + bi
    jj = np.arange(bc)[None, :] * 4 + bj
    values = small[ii, jj]  # (br, bc, 3): each block's brightest quarter-block
    lum_b = values.mean(axis=2)
    # centres of those quarter-blocks in grid pixels
    ci = (ii + 0.5) * rows / small.shape[0]
    cj = (jj + 0.5) * cols / small.shape[1]
    keep = lum_b >= 0.8 * np.percentile(lum_b, 90)
    G = np.column_stack([np.ones(lum_b.size), cj.ravel(), ci.ravel()])
    Y = values.reshape(-1, 3)
    coef = np.zeros((3, 3))
    for _ in range(2):
        sel = keep.ravel()
        if sel.sum() < 3:
            return np.array([[float(np.percentile(Y[:, c], 90)), 0.0, 0.0] for c in range(3)])
        coef = np.linalg.lstsq(G[sel], Y[sel], rcond=None)[0].T  # (3 channels, 3 coefficients)
        fit = (G @ coef.T).mean(axis=1).reshape(lum_b.shape)
        keep = keep & (lum_b >= 0.92 * fit)
    return coef


class InkClassifier:
    """Classifies rectified board images of one grid shape; buffers reused frame to frame."""

    def __init__(self, params: InkParams, looked_at: np.ndarray, resolution_m: float) -> None:
        self.p = params
        self.looked_at = looked_at
        self.M, self.m = unmixing_matrix(ink_absorption(params), params.prior_weight)
        rows, cols = looked_at.shape
        self.block_px = max(int(round(WHITE_BLOCK_M / resolution_m)), 4)
        # per pixel [1, col, row]: the local white is cv2.transform of it with the (3, 3) fitted coefficients
        self._affine_basis = np.dstack([np.ones((rows, cols), np.float32),
                                        np.broadcast_to(np.arange(cols, dtype=np.float32)[None, :], (rows, cols)),
                                        np.broadcast_to(np.arange(rows, dtype=np.float32)[:, None], (rows, cols))])
        # [s, t] = M x + m and the model's residual e = x - A [s, t] = (I - A M) x - A m: both affine in x,
        # so each is one cv2.transform with a (k, 4) matrix (fused, float32, no temporaries per channel)
        A = np.column_stack([np.ones(3), -ink_absorption(params)])
        self._to_st = np.hstack([self.M, self.m[:, None]]).astype(np.float32)
        self._to_residual = np.hstack([np.eye(3) - A @ self.M, -(A @ self.m)[:, None]]).astype(np.float32)
        self._sum3 = np.ones((1, 3), np.float32)
        r = int(np.ceil(params.occlusion_margin_m / resolution_m))
        self._grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)) if r > 0 else None
        c = int(np.ceil(params.occlusion_fill_m / resolution_m / 2))
        self._fill = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * c + 1, 2 * c + 1)) if c > 0 else None

    def classify(self, rect_rgb: np.ndarray, hidden: np.ndarray | None = None) -> InkMap:
        """The :class:`InkMap` of ``rect_rgb`` (rows, cols, 3) uint8 RGB; ``hidden`` (rows, cols) bool: pixels
        known to show something else than the board (the robot's tool, :mod:`perception.self_filter`), occluded
        whatever their colour."""
        p = self.p
        rgb = rect_rgb.astype(np.float32)
        coef = fit_white(rgb, self.looked_at, self.block_px)
        white = cv2.transform(self._affine_basis, coef.astype(np.float32))  # (rows, cols, 3)
        np.maximum(white, 1.0, out=white)
        x = cv2.divide(rgb, white)
        s, t = cv2.split(cv2.transform(x, self._to_st))
        e = cv2.transform(x, self._to_residual)
        residual2 = cv2.transform(cv2.multiply(e, e), self._sum3)
        d = cv2.divide(t, s)  # s ~ 0 (black: outside the camera image) is out of the illumination range below
        lo, hi = p.illumination_range
        ok = cv2.inRange(s, lo, hi) & cv2.inRange(d, D_RANGE[0], D_RANGE[1]) \
            & cv2.inRange(residual2, -1.0, p.max_residual ** 2)
        bad = ok == 0
        if hidden is not None:
            bad |= hidden
        if self._fill is not None:  # highlights on the arm, gaps between its links: not board to judge
            bad |= ~self.looked_at
            bad = cv2.morphologyEx(bad.view(np.uint8), cv2.MORPH_CLOSE, self._fill).view(bool)
        bad &= self.looked_at
        if self._grow is not None:
            bad = cv2.dilate(bad.view(np.uint8), self._grow).view(bool)
        occluded = bad & self.looked_at
        visible = self.looked_at & ~occluded
        d = np.where(visible, np.clip(d, 0.0, 1.0), 0.0).astype(np.float32)
        return InkMap(d, occluded, visible & (d >= p.stain_level), self.looked_at)
