"""Board pixels as clean board, stain of one of several inks, or occluded, in a colour model of ink on a white board.

A board pixel's colour ``I`` (3,), divided by the local white ``W`` (3,)
(the clean board under this frame's light), is modelled, for each ink
``k`` of the palette (``[perception.ink] inks``), as::

    x = I / W = s (1 - d a_k),        a_k = 1 - ink_k / board_rgb

with ``s`` the illumination relative to ``W`` (shading, a soft shadow) and
``d`` the ink fraction (0 clean, 1 full ink). With ``t = s d`` the model is
linear, ``x = s 1 - t a_k``; ``(s, t)`` come per pixel from a least-squares
fit with a weak prior ``s ~ 1`` (weight ``prior_weight``, which decides
between shade and ink when the ink is neutral, e.g. black)::

    [s, t] = (A^T A + lambda e1 e1^T)^-1 (A^T x + lambda e1),   A = [1 | -a_k]  (3, 2)

and the pixel takes the ink whose model leaves the smallest residual (the
ink each stain reports). ``d = t / s`` does not change when ``W`` is off
by a factor, so a light gradient only moves ``s``.

A pixel is *occluded* (the arm, the eraser, a deep shadow, anything that is
not board) when ``s`` is outside ``illumination_range``, when the colour is
farther than ``max_residual + chroma_tolerance d`` from every ink's model,
when it lies outside the camera image, or when the caller knows it hidden
(the robot's own tool, whose colour may be the ink's:
:mod:`perception.self_filter`). Such pixels in specks narrower than
``occlusion_min_m`` are not occluded (a stroke's colour fringe, a JPEG
block: too small to hide anything); occluded areas are closed over gaps
narrower than ``occlusion_fill_m`` (highlights on the arm that look like
white board) and grow by ``occlusion_margin_m`` to catch mixed pixels at
their edges. Otherwise it is *stain* when ``d >= stain_level``, else
*clean* (at or below ``clean_level``: clean; between: faint ink, the
ghost an eraser leaves, which counts in a stain's remaining ink but never
starts a stain). The thresholds are on the ink fraction relative to the
local white, so they adapt to the light; no grey level is fixed.

``W`` has two parts. The board-wide white ``W_g`` is an affine function of
the board coordinates per channel (a light gradient), fitted each frame to
the typical (upper-quartile) brightness of blocks of the rectified image, refitted
without the blocks far off the first fit (the arm, big shadows, solid
stains, glare). With ``white_fill_m > 0`` the local white follows the light
closer (a real room: glare from a window, a lamp's hot spot, shadows):
the image averaged over cells of a quarter of ``white_fill_m`` and
closed (a grey-level closing: the dark filled, a step kept) over
``white_fill_m`` (strokes and letters filled, a glare's edge kept), kept
within ``white_follow`` times ``W_g`` (a solid stain wider than the fill is
not taken for a shadow). Glare is then white board, never ink; ink under
glare keeps what contrast it has left.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .occlusion import BorderClosing, open_local
from .params import InkParams
from .unmix import finish_into, unmix_into

#: Side of the blocks the board-wide white is measured on [m].
WHITE_BLOCK_M = 0.05
#: A channel this bright is clipped by the sensor (glare): no colour is measured there.
SATURATED = 250
#: Ink fractions outside this are not ink on a board.
D_RANGE = (-0.3, 1.6)


@dataclass
class InkMap:
    """One frame's classification of the rectified board image, all (rows, cols).

    d : float32 ink fraction (0 where not judged). ink : uint8 index into
    ``names`` of the ink that explains each pixel best (meaningful where
    ``d > 0``). occluded : bool, not board or not seen. stain : bool, board
    with ``d >= stain_level``. looked_at : bool, pixels judged at all (board
    minus edges and markers). names : the palette's ink names.
    """

    d: np.ndarray
    occluded: np.ndarray
    stain: np.ndarray
    looked_at: np.ndarray
    ink: np.ndarray | None = None
    names: tuple[str, ...] = ("ink",)

    @property
    def visible(self) -> np.ndarray:
        return self.looked_at & ~self.occluded


def ink_absorptions(params: InkParams) -> np.ndarray:
    """(k, 3) absorption ``a_k = 1 - ink_k / board`` per ink and RGB channel, in palette order."""
    board = np.array(params.board_rgb)
    return np.array([1.0 - np.array(rgb) / board for rgb in params.inks.values()])


def unmixing_matrix(a: np.ndarray, prior_weight: float) -> tuple[np.ndarray, np.ndarray]:
    """``(M (2, 3), m (2,))`` with ``[s, t] = M x + m`` the regularised least-squares fit of ``x = s 1 - t a``."""
    A = np.column_stack([np.ones(3), -a])
    N = A.T @ A + np.diag([prior_weight, 0.0])
    Ninv = np.linalg.inv(N)
    return Ninv @ A.T, Ninv @ np.array([prior_weight, 0.0])


def fit_white(rgb: np.ndarray, looked_at: np.ndarray, block_px: int) -> np.ndarray:
    """(3, 3) coefficients ``W_c(col, row) = c0 + c1 col + c2 row`` of the board-wide white per channel.

    rgb : (rows, cols, 3) float32. A block's white is the upper quartile of
    its 16 quarter-block averages (typical board, not its brightest patch:
    clean board then reads as no ink; ink over most of a block does not
    lower it); blocks outside 75-130 % of the typical block
    are ignored, then those more than 15 %, then 8 %, off the previous fit
    (the arm, shadows, solid stains, glare).
    """
    rows, cols = looked_at.shape
    q = max(block_px // 4, 1)
    small = cv2.resize(rgb, (max(cols // q, 1), max(rows // q, 1)), interpolation=cv2.INTER_AREA)
    ok = cv2.resize(looked_at.astype(np.float32), (small.shape[1], small.shape[0]), interpolation=cv2.INTER_AREA) > 0.99
    br, bc = small.shape[0] // 4, small.shape[1] // 4
    if br == 0 or bc == 0:
        return np.array([[float(np.max(small[..., c])), 0.0, 0.0] for c in range(3)])
    cells = small[:br * 4, :bc * 4].reshape(br, 4, bc, 4, 3).transpose(0, 2, 1, 3, 4).reshape(br, bc, 16, 3)
    good = ok[:br * 4, :bc * 4].reshape(br, 4, bc, 4).transpose(0, 2, 1, 3).reshape(br, bc, 16)
    lum = np.where(good, cells.mean(axis=3), -np.inf)
    n_good = good.sum(axis=2)  # (br, bc)
    order = np.argsort(lum, axis=2)  # judged cells last, brightest at the end
    rank = 16 - n_good + (3 * n_good) // 4  # the upper quartile of the judged cells
    pick = np.take_along_axis(order, np.minimum(rank, 15)[..., None], axis=2)[..., 0]
    found = n_good > 0
    values = np.take_along_axis(cells, pick[..., None, None], axis=2)[:, :, 0]  # (br, bc, 3): that cell
    lum_b = np.where(found, values.mean(axis=2), 0.0)
    ci = ((np.arange(br)[:, None] * 4 + pick // 4) + 0.5) * rows / small.shape[0]
    cj = ((np.arange(bc)[None, :] * 4 + pick % 4) + 0.5) * cols / small.shape[1]
    if not found.any():
        return np.array([[float(np.max(small[..., c])), 0.0, 0.0] for c in range(3)])
    typical = float(np.median(lum_b[found]))
    keep = found & (lum_b >= 0.75 * typical) & (lum_b <= 1.3 * typical)
    G = np.column_stack([np.ones(lum_b.size), cj.ravel(), ci.ravel()])
    Y = values.reshape(-1, 3)
    coef = np.zeros((3, 3))
    for tol in (0.15, 0.08):  # refit without the blocks far from the fit: the arm, shadows, solid stains, glare
        sel = keep.ravel()
        if sel.sum() < 3:
            return np.array([[float(np.percentile(Y[:, c], 90)), 0.0, 0.0] for c in range(3)])
        coef = np.linalg.lstsq(G[sel], Y[sel], rcond=None)[0].T  # (3 channels, 3 coefficients)
        fit = (G @ coef.T).mean(axis=1).reshape(lum_b.shape)
        keep = found & (np.abs(lum_b - fit) <= tol * fit)
    return coef


class InkClassifier:
    """Classifies rectified board images of one grid shape; buffers reused frame to frame."""

    def __init__(self, params: InkParams, looked_at: np.ndarray, resolution_m: float) -> None:
        self.p = params
        self.looked_at = looked_at
        self.names = params.ink_names
        rows, cols = looked_at.shape
        self.block_px = max(int(round(WHITE_BLOCK_M / resolution_m)), 4)
        # per pixel [1, col, row]: the board-wide white is cv2.transform of it with the (3, 3) fitted coefficients
        self._affine_basis = np.dstack([np.ones((rows, cols), np.float32),
                                        np.broadcast_to(np.arange(cols, dtype=np.float32)[None, :], (rows, cols)),
                                        np.broadcast_to(np.arange(rows, dtype=np.float32)[:, None], (rows, cols))])
        # per ink, [s, t] = M x + m and the model's residual e = x - A [s, t] = (I - A M) x - A m: both affine in
        # x, so each is one cv2.transform with a (k, 4) matrix (fused, float32, no temporaries per channel)
        to_st, to_residual = [], []
        for a in ink_absorptions(params):
            M, m = unmixing_matrix(a, params.prior_weight)
            A = np.column_stack([np.ones(3), -a])
            to_st.append(np.hstack([M, m[:, None]]).astype(np.float32))
            to_residual.append(np.hstack([np.eye(3) - A @ M, -(A @ m)[:, None]]).astype(np.float32))
        self._to_st, self._to_residual = np.array(to_st), np.array(to_residual)  # (k, 2, 4), (k, 3, 4)
        self._limits = np.array([*params.illumination_range, *D_RANGE, params.max_residual, params.chroma_tolerance],
                                np.float32)
        self._no_local, self._no_edges = np.zeros((0, 0, 3), np.float32), np.zeros((0, 0), bool)
        self._follow = np.array(params.white_follow, np.float32)
        self._sum3 = np.ones((1, 3), np.float32)
        r = int(np.ceil(params.occlusion_margin_m / resolution_m))
        self._grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)) if r > 0 else None
        o = int(np.ceil(params.occlusion_min_m / resolution_m / 2))
        self._speck = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * o + 1, 2 * o + 1)) if o > 0 else None
        c = int(np.ceil(params.occlusion_fill_m / resolution_m / 2))
        self._fill = BorderClosing(~looked_at, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * c + 1, 2 * c + 1))
                                   ) if c > 0 else None
        # the local white: cells of a quarter of white_fill_m, closed over white_fill_m (4 cells + 1)
        self._cell = max(int(round(params.white_fill_m / 4 / resolution_m)), 1) if params.white_fill_m > 0 else 0
        if self._cell:
            self._close_kernel = np.ones((5, 5), np.uint8)
            self._edge_kernel = np.ones((5, 5), np.uint8)

    def local_white(self, rgb: np.ndarray, white_g: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """``(W, edges)``: the white under this frame's light near each pixel, (rows, cols, 3) float32 (module
        docstring), and (rows, cols) bool where the light changes too fast to judge ink (a glare's or a shadow's
        edge), or None without a local white."""
        if not self._cell:
            return white_g, None
        local, edges = self._local_unkept(rgb)
        lo, hi = self.p.white_follow
        return np.minimum(np.maximum(local, white_g * lo), white_g * hi), edges

    def _local_unkept(self, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The local white before it is kept within ``white_follow`` of the board-wide white, and the light steps
        (:meth:`local_white`; the keeping is done per pixel in :func:`~perception.unmix.unmix_into`)."""
        rows, cols = self.looked_at.shape
        k = self._cell
        small = cv2.resize(rgb, (max(cols // k, 1), max(rows // k, 1)), interpolation=cv2.INTER_AREA)
        small = cv2.morphologyEx(small, cv2.MORPH_CLOSE, self._close_kernel)
        lum = small.mean(axis=2)
        spread = cv2.morphologyEx(lum, cv2.MORPH_GRADIENT, self._edge_kernel)
        edges = (spread > self.p.light_step * cv2.dilate(lum, self._edge_kernel)).view(np.uint8)
        edges = cv2.resize(edges, (cols, rows), interpolation=cv2.INTER_NEAREST).view(bool)
        small = cv2.blur(small, (3, 3))
        return cv2.resize(small, (cols, rows), interpolation=cv2.INTER_LINEAR), edges

    def classify(self, rect_rgb: np.ndarray, hidden: np.ndarray | None = None) -> InkMap:
        """The :class:`InkMap` of ``rect_rgb`` (rows, cols, 3) uint8 RGB; ``hidden`` (rows, cols) bool: pixels
        known to show something else than the board (the robot's tool, :mod:`perception.self_filter`), occluded
        whatever their colour."""
        p = self.p
        rgb = rect_rgb.astype(np.float32)
        coef = fit_white(rgb, self.looked_at, self.block_px).astype(np.float32)
        local, edges = self._local_unkept(rgb) if self._cell else (self._no_local, self._no_edges)
        # per pixel: the white W (the affine fit), x = rgb / W, or with a local white L (kept within white_follow
        # of W) x = 1 - (L - rgb) / min(L, W) (light above the board's own white is added, glare: ink takes away
        # a share of the board's white), unmixed per ink, one compiled pass
        rows, cols = self.looked_at.shape
        d, ink, bad8 = (np.empty((rows, cols), np.float32), np.empty((rows, cols), np.uint8),
                        np.empty((rows, cols), np.uint8))
        unmix_into(rect_rgb, coef, local, self._follow, edges, self._to_st, self._to_residual, self._limits,
                   SATURATED, d, ink, bad8)
        bad = bad8.view(bool)
        if self._speck is not None:  # colour fringes at strokes, JPEG blocks: too small to be the arm
            bad = open_local(bad.view(np.uint8), self._speck).view(bool)
        if hidden is not None:
            bad |= hidden
        if self._fill is not None:  # highlights on the arm, gaps between its links: not board to judge
            # closed together with the border never judged (what is not board there is in the border already)
            bad = self._fill.close((bad & self.looked_at).view(np.uint8)).view(bool)
        bad &= self.looked_at
        if self._grow is not None:
            bad = cv2.dilate(bad.view(np.uint8), self._grow).view(bool)
        occluded = bad & self.looked_at
        stain = np.empty(occluded.shape, bool)
        finish_into(d, occluded, self.looked_at, p.stain_level, stain)
        return InkMap(d, occluded, stain, self.looked_at, ink, self.names)
