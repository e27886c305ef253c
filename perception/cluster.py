"""Stain pixels into stains: the paper's pixel clustering (III-C), with the number of stains not given.

Single-linkage clustering with link distance ``eps`` (equivalently DBSCAN
with ``min_samples = 1``): two stain pixels belong to the same stain when a
chain of stain pixels joins them with steps no longer than ``eps``. On a
pixel grid this is cheap: grow every pixel by a disc of radius
``eps / 2`` (two discs touch when their centres are at most ``eps`` apart),
label the connected components of the grown mask, and give each pixel its
component. On the grid the link is eps up to eps + 1.5 px (digital discs
touch a little early), which the tests check against scikit-learn's DBSCAN. Each cluster then yields the anchor
``y_m`` (its centre) and the amplitude scale ``r`` (its extent) the planner needs
(:func:`interfaces.stain_shape.shape_of`).
"""

from __future__ import annotations

import cv2
import numpy as np


def disc(radius_px: float) -> np.ndarray:
    """A (2k+1, 2k+1) uint8 disc of ``radius_px`` (k = floor of it) for morphology."""
    k = int(np.floor(radius_px))
    y, x = np.mgrid[-k:k + 1, -k:k + 1]
    return (x * x + y * y <= radius_px * radius_px + 1e-9).astype(np.uint8)


def cluster_pixels(mask: np.ndarray, eps_px: float) -> tuple[int, np.ndarray]:
    """``(n, labels)``: single-linkage clusters of the True pixels of ``mask`` (rows, cols).

    labels : (rows, cols) int32, 1..n on mask pixels (numbered in raster order of their first pixel), 0
    elsewhere. The work is done on the bounding box of the True pixels grown by the disc (a board's ink covers
    a small share of it): the same labels as on the whole image.
    """
    out = np.zeros(mask.shape, np.int32)
    x, y, w, h = cv2.boundingRect(mask.view(np.uint8))
    if w == 0:
        return 0, out
    k = int(np.floor(eps_px / 2.0)) + 1 if eps_px >= 2.0 else 1
    r0, r1, c0, c1 = max(y - k, 0), min(y + h + k, mask.shape[0]), max(x - k, 0), min(x + w + k, mask.shape[1])
    sub = mask[r0:r1, c0:c1]
    grown = cv2.dilate(sub.view(np.uint8), disc(eps_px / 2.0)) if eps_px >= 2.0 else sub.view(np.uint8)
    n, comp = cv2.connectedComponents(grown, connectivity=8, ltype=cv2.CV_32S)
    labels = np.where(sub, comp, 0)
    used = np.unique(labels[labels > 0])
    if used.size != n - 1:  # renumber 1..n
        lut = np.zeros(n, np.int32)
        lut[used] = np.arange(1, used.size + 1)
        labels = lut[labels]
    out[r0:r1, c0:c1] = labels
    return int(used.size), out
