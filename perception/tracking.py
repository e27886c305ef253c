"""Stains followed frame to frame on the rectified board: stable ids, regions, remaining and visible fractions, kappa.

A stain is born from a cluster of stain pixels (:func:`~perception.cluster.cluster_pixels`)
that stays for ``confirm_s``. From then on it owns a *region*: the pixels
ever seen as its ink (its *core*), grown by ``region_margin_m``. Stain
pixels within ``link_m`` of a core join it (the rest of a stain the arm hid
at first, ink smeared by the eraser); stain pixels farther away start new
candidates. Per region pixel the tracker keeps

- ``d_ref``: the most ink seen there (the stain at its first sighting,
  since wiping only removes ink),
- ``d_last``: the ink at its last visible observation, and when that was.

Fractions of a stain::

    remaining = sum(d_last - c)+ / sum(d_ref - c)+   over its region, c = clean_level
    visible   = visible pixels / region pixels  (this frame)
    seen      = pixels observed within memory_s / region pixels

so a pixel the arm or the eraser hides keeps its last observation and never
turns clean by being hidden, and the faint ghost an eraser leaves (ink
fraction at or below ``clean_level``) is no ink left. With several inks
(``[perception.ink] inks``) each stroke takes one ink
(:func:`~perception.ink_areas.drawing_inks`), each ink is clustered on its
own and a stain grows only by its own ink: every stain has one colour. The *ink* of a stain is its region's pixels
whose last observation still holds ink (``d_last >= ink_level``): its
shape (centre, size, width, axis) is what adaptive wiping follows,
refreshed every :data:`INK_EVERY_S` (the controller re-targets at most
every 0.5 s; a shape costs ~0.1-0.3 ms per stain). kappa (:class:`~perception.kappa.KappaLatch`)
needs ``seen >= min_seen``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from interfaces.stain_shape import Shape, shape_of

from .classify import InkMap
from .cluster import cluster_pixels, disc
from .ink_areas import drawing_inks
from .kappa import KappaLatch
from .params import KappaParams, StainParams
from .rectify import BoardGrid
from .track_kernels import observe_into

#: The shape of a stain's remaining ink is refreshed at most this often [s].
INK_EVERY_S = 0.2


@dataclass
class _Candidate:
    centre_px: np.ndarray
    first_t: float
    last_t: float
    frames: int
    mask: np.ndarray
    colour: int = 0


@dataclass
class Track:
    """One stain. Arrays are (rows, cols) over the rectified grid; ``box`` = (r0, r1, c0, c1) bounds the region."""

    id: int
    core: np.ndarray
    region: np.ndarray
    d_ref: np.ndarray
    d_last: np.ndarray
    t_seen: np.ndarray
    latch: KappaLatch
    box: tuple[int, int, int, int]
    shape: Shape | None = None
    ink: Shape | None = None
    ink_t: float = -np.inf
    remaining: float = 1.0
    visible: float = 0.0
    seen: float = 0.0
    born_t: float = 0.0
    colour: int = 0
    reach: np.ndarray | None = None  # (box rows, box cols) bool: the core grown by link_m (kept while it holds)
    near: np.ndarray | None = None  # (box rows, box cols) bool: the region grown by link_m
    shape_stale: bool = True  # the core changed since ``shape`` was measured

    @property
    def kappa(self) -> bool:
        return self.latch.kappa


def _box_of(mask: np.ndarray, pad: int) -> tuple[int, int, int, int]:
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    r, c = mask.shape
    return (max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, r), max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, c))


class StainTracker:
    """All stains of one board; :meth:`update` once per classified frame."""

    def __init__(self, grid: BoardGrid, stains: StainParams, kappa: KappaParams, ink_level: float = 0.3,
                 clean_level: float = 0.0) -> None:
        self.grid = grid
        self.ink_level = ink_level  # darkness from which a pixel's last observation counts as ink left
        self.clean_level = clean_level  # ink fraction at or below which a pixel counts as clean (a ghost)
        self.p = stains
        self.kp = kappa
        res = grid.resolution_m
        self.link_px = stains.link_m / res
        self.min_px = max(int(np.ceil(stains.min_area_m2 / (res * res))), 1)
        self._margin = disc(stains.region_margin_m / res)
        self._link = disc(self.link_px)
        self._pad = int(np.ceil(self.link_px + stains.region_margin_m / res)) + 1
        self.tracks: list[Track] = []
        self._candidates: list[_Candidate] = []
        self._next_id = 0
        self.merges = 0

    # -- per frame -------------------------------------------------------------------------------------

    def update(self, ink: InkMap, t_s: float) -> None:
        """Follow the stains into the frame of ``ink`` taken at ``t_s`` [s]."""
        visible = ink.visible
        strokes = None if ink.ink is None or len(ink.names) == 1 else drawing_inks(ink, self.link_px)
        owned = np.zeros(visible.shape, bool)
        for tr in self.tracks:
            self._grow(tr, ink, owned, strokes)
            owned |= tr.region
        self._merge_touching()
        for tr in self.tracks:
            self._observe(tr, ink, visible, t_s)
        near = owned.copy()  # within link_m of a stain's region: each region grown inside its box (it fits there)
        for tr in self.tracks:
            r0, r1, c0, c1 = tr.box
            near[r0:r1, c0:c1] |= tr.near
        free = ink.stain & ~near
        if not free.any():  # no new ink anywhere: every candidate is gone (what each ink's search would find)
            self._candidates = []
        elif strokes is None:
            self._detect(free, ink, visible, t_s, 0)
        else:
            present = np.bincount(strokes[free], minlength=len(ink.names))  # free pixels per ink
            for k in range(len(ink.names)):
                self._detect(free & (strokes == k) if present[k] else None, ink, visible, t_s, k)

    def _grow(self, tr: Track, ink: InkMap, owned: np.ndarray, strokes: np.ndarray | None) -> None:
        """Stain pixels of the stain's ink within ``link_m`` of the core (and nobody's) join the stain."""
        r0, r1, c0, c1 = tr.box
        new = tr.reach & ink.stain[r0:r1, c0:c1] & ~tr.core[r0:r1, c0:c1] & ~owned[r0:r1, c0:c1]
        if strokes is not None:
            new &= strokes[r0:r1, c0:c1] == tr.colour
        if not new.any():
            return
        tr.core[r0:r1, c0:c1] |= new
        if _box_of(tr.core, self._pad) != tr.box:
            self._set_region(tr)
            return
        # the box holds: region, reach and near grow by the new pixels' own dilations (a dilation of a union is the
        # union of the dilations), worked out on the new pixels' box grown by the kernels' reach
        x, y, w, h = cv2.boundingRect(new.view(np.uint8))
        pad = self._margin.shape[0] // 2 + self._link.shape[0] // 2 + 1
        i0, i1, j0, j1 = max(y - pad, 0), min(y + h + pad, r1 - r0), max(x - pad, 0), min(x + w + pad, c1 - c0)
        sub = new[i0:i1, j0:j1].view(np.uint8)
        grown = cv2.dilate(sub, self._margin)
        assert tr.reach is not None and tr.near is not None  # set with the box (_set_region)
        tr.region[r0 + i0:r0 + i1, c0 + j0:c0 + j1] |= grown.view(bool)
        tr.reach[i0:i1, j0:j1] |= cv2.dilate(sub, self._link).view(bool)
        tr.near[i0:i1, j0:j1] |= cv2.dilate(grown, self._link).view(bool)
        tr.shape_stale = True

    def _merge_touching(self) -> None:
        """Stains of one ink whose cores have come within ``link_m`` of each other are one stain (the clustering's
        rule, kept over time: a faint drawing seen piece by piece, the arm having split it at first), the older
        id kept; kappa only if both had it."""
        i = 0
        while i < len(self.tracks):
            a = self.tracks[i]
            r0, r1, c0, c1 = a.box
            for b in list(self.tracks[i + 1:]):
                q0, q1, p0, p1 = b.box
                if b.colour != a.colour or q0 >= r1 or r0 >= q1 or p0 >= c1 or c0 >= p1:
                    continue
                if not (a.reach & b.core[r0:r1, c0:c1]).any():
                    continue
                a.core |= b.core
                np.maximum(a.d_ref, b.d_ref, out=a.d_ref)
                np.copyto(a.d_last, b.d_last, where=b.t_seen > a.t_seen)
                np.maximum(a.t_seen, b.t_seen, out=a.t_seen)
                a.latch.kappa = a.latch.kappa and b.latch.kappa
                self.tracks.remove(b)
                self._set_region(a)
                r0, r1, c0, c1 = a.box
                self.merges += 1
            i += 1

    def _set_region(self, tr: Track) -> None:
        """After the core changed: its box, region, the core and the region grown by ``link_m`` (each fits in
        the box: the box reaches ``link_m`` + ``region_margin_m`` + 1 px past the core), the shape to measure."""
        tr.box = _box_of(tr.core, self._pad)
        r0, r1, c0, c1 = tr.box
        core = tr.core[r0:r1, c0:c1].view(np.uint8)
        tr.region[r0:r1, c0:c1] = cv2.dilate(core, self._margin).view(bool)
        tr.reach = cv2.dilate(core, self._link).view(bool)
        tr.near = cv2.dilate(tr.region[r0:r1, c0:c1].view(np.uint8), self._link).view(bool)
        tr.shape_stale = True

    def _observe(self, tr: Track, ink: InkMap, visible: np.ndarray, t_s: float) -> None:
        r0, r1, c0, c1 = tr.box
        reg = tr.region[r0:r1, c0:c1]
        d = cv2.blur(ink.d[r0:r1, c0:c1], (3, 3))  # 3x3 mean: the reference, a maximum over time, not raised by noise
        d_last = tr.d_last[r0:r1, c0:c1]
        n, ref, left, n_vis, n_seen = observe_into(reg, visible[r0:r1, c0:c1], d, d_last, tr.d_ref[r0:r1, c0:c1],
                                                   tr.t_seen[r0:r1, c0:c1], t_s, self.clean_level, self.kp.memory_s)
        tr.remaining = float(np.clip(left / ref, 0.0, 1.0)) if ref > 0 else 1.0
        tr.visible = n_vis / max(n, 1)
        tr.seen = n_seen / max(n, 1)
        tr.latch.update(t_s, tr.remaining, tr.seen)
        if tr.shape_stale:
            tr.shape_stale = False
            rows, cols = np.nonzero(tr.core[r0:r1, c0:c1])
            if rows.size:
                tr.shape = shape_of(self.grid.xy_of(rows + r0, cols + c0), self.grid.resolution_m)
        if t_s - tr.ink_t >= INK_EVERY_S or t_s < tr.ink_t:
            tr.ink_t = t_s
            rows, cols = np.nonzero(reg & (d_last >= self.ink_level))
            tr.ink = shape_of(self.grid.xy_of(rows + r0, cols + c0), self.grid.resolution_m) if rows.size else None

    def _detect(self, free: np.ndarray | None, ink: InkMap, visible: np.ndarray, t_s: float, colour: int) -> None:
        """New clusters of ink ``colour`` (palette index) in ``free`` (None: none): candidates until seen for
        ``confirm_s``, then stains."""
        n, labels = cluster_pixels(free, self.link_px) if free is not None else (0, None)
        seen_now: list[tuple[np.ndarray, np.ndarray]] = []
        if n and labels is not None:
            counts = np.bincount(labels[free], minlength=n + 1)  # labels are 0 off the free pixels
            for k in np.flatnonzero(counts >= self.min_px):
                if k == 0:
                    continue
                mask = labels == k
                rows, cols = np.nonzero(mask)
                seen_now.append((np.array([rows.mean(), cols.mean()]), mask))
        mine = [c for c in self._candidates if c.colour == colour]
        kept: list[_Candidate] = []
        for centre, mask in seen_now:
            match = min(mine, key=lambda c: np.linalg.norm(c.centre_px - centre), default=None)
            if match is not None and np.linalg.norm(match.centre_px - centre) <= 2 * self.link_px \
                    and not any(match is k for k in kept):
                match.centre_px, match.last_t, match.frames, match.mask = centre, t_s, match.frames + 1, mask
                kept.append(match)
            else:
                kept.append(_Candidate(centre, t_s, t_s, 1, mask, colour))
        self._candidates = [c for c in self._candidates if c.colour != colour]
        for c in kept:
            if t_s - c.first_t >= self.p.confirm_s - 1e-9 and (c.frames >= 2 or self.p.confirm_s == 0):
                self._promote(c, ink, visible, t_s)
            else:
                self._candidates.append(c)

    def _promote(self, c: _Candidate, ink: InkMap, visible: np.ndarray, t_s: float) -> None:
        shape = c.mask.shape
        tr = Track(self._next_id, c.mask.copy(), np.zeros(shape, bool), np.zeros(shape, np.float32),
                   np.zeros(shape, np.float32), np.full(shape, -np.inf), KappaLatch(self.kp), (0, 0, 0, 0),
                   born_t=t_s, colour=c.colour)
        self._next_id += 1
        self._set_region(tr)
        self._observe(tr, ink, visible, t_s)
        self.tracks.append(tr)

    # -- queries ---------------------------------------------------------------------------------------

    def candidates(self) -> int:
        return len(self._candidates)

    def debug_labels(self) -> np.ndarray:
        """(rows, cols) int32: track index + 1 on each region, 0 elsewhere (for drawing)."""
        out = np.zeros(self.grid.shape, np.int32)
        for i, tr in enumerate(self.tracks):
            out[tr.region] = i + 1
        return out
