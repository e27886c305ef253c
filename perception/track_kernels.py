"""A stain's per-frame bookkeeping (:meth:`perception.tracking.StainTracker._observe`), compiled (numba).

Per pixel of a stain's region seen this frame, the last observation and the
most ink seen are updated, and the sums behind its fractions are taken in
the same pass (:mod:`perception.tracking`'s module docstring). As array
operations this was a dozen masked copies and reductions over the stain's
box per stain per frame (~0.6 ms each for a handwritten word's box); here it
is one loop over the box. Sums are in float64.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True, error_model="numpy")
def observe_into(region: np.ndarray, visible: np.ndarray, d: np.ndarray, d_last: np.ndarray, d_ref: np.ndarray,
                 t_seen: np.ndarray, t_s: float, clean_level: float, memory_s: float) -> tuple[int, float, float, int,
                                                                                                 int]:
    """Update one stain's box in place and return ``(n, ref, left, n_visible, n_seen)``.

    region, visible : (rows, cols) bool, the stain's region and this frame's visible pixels over its box.
    d : (rows, cols) float32, this frame's ink fraction (3x3 mean). d_last, d_ref : (rows, cols) float32, the
    last observation and the most ink seen; t_seen : (rows, cols) float64, when each was last seen [s]. Over
    the region: ``n`` pixels, ``ref = sum(d_ref - c)+``, ``left = sum(d_last - c)+`` (c = ``clean_level``),
    ``n_visible`` seen this frame, ``n_seen`` seen within ``memory_s`` of ``t_s``.
    """
    rows, cols = region.shape
    n = 0
    n_vis = 0
    n_seen = 0
    ref = 0.0
    left = 0.0
    c = np.float32(clean_level)
    for i in range(rows):
        for j in range(cols):
            if not region[i, j]:
                continue
            n += 1
            if visible[i, j]:
                v = d[i, j]
                d_last[i, j] = v
                t_seen[i, j] = t_s
                if v > d_ref[i, j]:
                    d_ref[i, j] = v
                n_vis += 1
            ref += max(d_ref[i, j] - c, np.float32(0.0))
            left += max(d_last[i, j] - c, np.float32(0.0))
            if t_s - t_seen[i, j] <= memory_s:
                n_seen += 1
    return n, ref, left, n_vis, n_seen
