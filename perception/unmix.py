"""The per-pixel colour unmixing of :mod:`perception.classify`, compiled (numba): one pass over the board image.

The model is :mod:`perception.classify`'s (its module docstring): per
pixel the colour relative to the white, ``x`` (3,), is fitted for each ink
``k`` as ``[s, t] = M_k x + m_k`` with residual ``e = (I - A_k M_k) x - A_k
m_k``; the pixel takes the ink of the smallest ``|e|^2`` (the first on a
tie), ``d = t / s``, and is *bad* (not board) when ``s`` is outside the
illumination range, ``d`` outside :data:`~perception.classify.D_RANGE`, or
``|e| > max_residual + chroma_tolerance clip(d, 0, 1)``; with the local
white also when a channel is clipped (``>= SATURATED``) or the light steps.

As numpy/OpenCV array operations this cost a pair of ``cv2.transform``
calls per ink plus a dozen full-image temporaries (a real board with six
inks: ~40 ms a 0.8 x 0.7 m board at 2 mm). Here it is one loop over the
pixels that reads the rectified image and the white once, keeps every
intermediate in registers and writes ``d``, the ink index and the bad mask:
the arithmetic is the same, in float32, with the reassociation and
contraction of ``fastmath`` (no assumption about NaN or infinity): results
equal the array formulation within float32 rounding
(``tests/test_perception_rate.py``).
``cache=True`` keeps the machine code in ``__pycache__`` (or
``NUMBA_CACHE_DIR``); the kernel lets go of the GIL (``nogil``: a frame's
few milliseconds should not hold the service's Zenoh threads).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"nsz", "arcp", "contract", "reassoc"})
def unmix_into(rgb: np.ndarray, white_coef: np.ndarray, local: np.ndarray, follow: np.ndarray, edges: np.ndarray,
               to_st: np.ndarray, to_res: np.ndarray, limits: np.ndarray, saturated: int, d_out: np.ndarray,
               ink_out: np.ndarray, bad_out: np.ndarray) -> None:
    """Fill ``d_out`` (rows, cols) float32, ``ink_out`` (rows, cols) uint8 and ``bad_out`` (rows, cols) uint8 (1 =
    not board) from ``rgb`` (rows, cols, 3) uint8.

    white_coef : (3, 3) float32, the board-wide white ``W_c = max(c0 + c1 col + c2 row, 1)`` per channel
    (:func:`~perception.classify.fit_white`). local : (rows, cols, 3) float32, the local white before it is kept
    within ``follow`` (2,) float32 times ``W`` (:meth:`~perception.classify.InkClassifier.local_white`), or shape
    (0, 0, 3) for none: then ``x = rgb / W``, else ``x = 1 - (L - rgb) / min(L, W)`` with ``L`` the kept local
    white. edges : (rows, cols) bool light steps (ignored without a local white). to_st : (k, 2, 4) float32,
    ``[s, t] = to_st[k] @ [x, 1]``; to_res : (k, 3, 4) float32, ``e = to_res[k] @ [x, 1]``. limits : float32
    ``[s_lo, s_hi, d_lo, d_hi, max_residual, chroma_tolerance]``. saturated : a channel at or above this is
    clipped (used with a local white only).
    """
    rows, cols = rgb.shape[0], rgb.shape[1]
    n_ink = to_st.shape[0]
    has_local = local.shape[0] == rows
    s_lo, s_hi, d_lo, d_hi, max_res, chroma = limits[0], limits[1], limits[2], limits[3], limits[4], limits[5]
    one = np.float32(1.0)
    zero = np.float32(0.0)
    x0 = np.empty(cols, np.float32)  # one row at a time: the loops over a row are simple enough to vectorise
    x1 = np.empty(cols, np.float32)
    x2 = np.empty(cols, np.float32)
    best = np.empty(cols, np.float32)
    s_best = np.empty(cols, np.float32)
    t_best = np.empty(cols, np.float32)
    k_best = np.empty(cols, np.uint8)
    lo, hi = follow[0], follow[1]
    for i in range(rows):
        fi = np.float32(i)
        w0 = white_coef[0, 0] + white_coef[0, 2] * fi  # the white's row part; its column part is added below
        w1 = white_coef[1, 0] + white_coef[1, 2] * fi
        w2 = white_coef[2, 0] + white_coef[2, 2] * fi
        for j in range(cols):
            fj = np.float32(j)
            v0 = max(w0 + white_coef[0, 1] * fj, one)
            v1 = max(w1 + white_coef[1, 1] * fj, one)
            v2 = max(w2 + white_coef[2, 1] * fj, one)
            if has_local:
                l0 = min(max(local[i, j, 0], v0 * lo), v0 * hi)
                l1 = min(max(local[i, j, 1], v1 * lo), v1 * hi)
                l2 = min(max(local[i, j, 2], v2 * lo), v2 * hi)
                x0[j] = one - (l0 - np.float32(rgb[i, j, 0])) / min(l0, v0)
                x1[j] = one - (l1 - np.float32(rgb[i, j, 1])) / min(l1, v1)
                x2[j] = one - (l2 - np.float32(rgb[i, j, 2])) / min(l2, v2)
            else:
                x0[j] = np.float32(rgb[i, j, 0]) / v0
                x1[j] = np.float32(rgb[i, j, 1]) / v1
                x2[j] = np.float32(rgb[i, j, 2]) / v2
        best[:] = np.float32(np.inf)
        for k in range(n_ink):
            a0, a1, a2, a3 = to_st[k, 0, 0], to_st[k, 0, 1], to_st[k, 0, 2], to_st[k, 0, 3]
            b0, b1, b2, b3 = to_st[k, 1, 0], to_st[k, 1, 1], to_st[k, 1, 2], to_st[k, 1, 3]
            p0, p1, p2, p3 = to_res[k, 0, 0], to_res[k, 0, 1], to_res[k, 0, 2], to_res[k, 0, 3]
            q0, q1, q2, q3 = to_res[k, 1, 0], to_res[k, 1, 1], to_res[k, 1, 2], to_res[k, 1, 3]
            r0, r1, r2, r3 = to_res[k, 2, 0], to_res[k, 2, 1], to_res[k, 2, 2], to_res[k, 2, 3]
            kk = np.uint8(k)
            for j in range(cols):
                u0, u1, u2 = x0[j], x1[j], x2[j]
                e0 = p0 * u0 + p1 * u1 + p2 * u2 + p3
                e1 = q0 * u0 + q1 * u1 + q2 * u2 + q3
                e2 = r0 * u0 + r1 * u1 + r2 * u2 + r3
                res2 = e0 * e0 + e1 * e1 + e2 * e2
                s = a0 * u0 + a1 * u1 + a2 * u2 + a3
                t = b0 * u0 + b1 * u1 + b2 * u2 + b3
                b = best[j]
                take = res2 < b  # the first ink on a tie
                best[j] = res2 if take else b
                s_best[j] = s if take else s_best[j]
                t_best[j] = t if take else t_best[j]
                k_best[j] = kk if take else k_best[j]
        for j in range(cols):
            s = s_best[j]
            d = t_best[j] / s if s != zero else zero  # OpenCV's divide: x / 0 = 0
            tol = max_res + chroma * min(max(d, zero), one)
            bad = not (s_lo <= s <= s_hi and d_lo <= d <= d_hi and best[j] <= tol * tol)
            if has_local and not bad:
                bad = edges[i, j] or rgb[i, j, 0] >= saturated or rgb[i, j, 1] >= saturated \
                    or rgb[i, j, 2] >= saturated
            d_out[i, j] = d
            ink_out[i, j] = k_best[j]
            bad_out[i, j] = 1 if bad else 0


@nb.njit(cache=True, nogil=True, error_model="numpy")
def finish_into(d: np.ndarray, occluded: np.ndarray, looked_at: np.ndarray, stain_level: float,
                stain_out: np.ndarray) -> None:
    """In place: ``d`` (rows, cols) float32 clipped to [0, 1] where visible (``looked_at`` and not ``occluded``,
    both bool) and 0 elsewhere; ``stain_out`` (rows, cols) bool: visible with ``d >= stain_level``."""
    rows, cols = d.shape
    lvl = np.float32(stain_level)
    for i in range(rows):
        for j in range(cols):
            if looked_at[i, j] and not occluded[i, j]:
                v = min(max(d[i, j], np.float32(0.0)), np.float32(1.0))
                d[i, j] = v
                stain_out[i, j] = v >= lvl
            else:
                d[i, j] = np.float32(0.0)
                stain_out[i, j] = False
