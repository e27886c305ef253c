"""What the centre and the size of a stain mean: one definition for the sim's truth and for perception.

A stain is a set of square cells (the sim's dirt grid, perception's
rectified pixels) of side ``res``. Its centre is the mean of the cell
centres; its extents along board x and y span the outer cell edges; its
size (``StainObservation.size_m``, ``SimTruth.sizes_m``: "the larger
extent") is the span along its principal axis, the direction of largest
spread; its width the span across it, and its axis the principal axis's
direction from board x, in (-pi/2, pi/2].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Shape:
    """Centre, extents and size of a set of board points.

    centre_m (2,), extent_m (2,) along board x and y, size_m the extent
    along the principal axis (the larger extent of the stain), area_m2,
    width_m the extent across the principal axis, axis_rad its direction
    [rad] in (-pi/2, pi/2]; all from points ``xy`` (n, 2) [m] that are
    centres of square pixels of side ``res`` (so one pixel has extent
    ``res``).
    """

    centre_m: np.ndarray
    extent_m: np.ndarray
    size_m: float
    area_m2: float
    width_m: float = 0.0
    axis_rad: float = 0.0


def shape_of(xy: np.ndarray, res: float) -> Shape:
    """The :class:`Shape` of pixel centres ``xy`` (n >= 1, 2) [m] on a grid of pitch ``res`` [m]."""
    centre = xy.mean(axis=0)
    extent = np.ptp(xy, axis=0) + res
    if len(xy) >= 3:
        cov = np.cov((xy - centre).T)
        _, vecs = np.linalg.eigh(cov)
        along = (xy - centre) @ vecs[:, -1]
        size = float(np.ptp(along) + res)
        width = float(np.ptp((xy - centre) @ vecs[:, 0]) + res)
        axis = math.atan2(vecs[1, -1], vecs[0, -1])
    else:
        size, width = float(extent.max()), float(extent.min())
        axis = 0.0 if extent[0] >= extent[1] else math.pi / 2
    if axis <= -math.pi / 2:
        axis += math.pi
    elif axis > math.pi / 2:
        axis -= math.pi
    return Shape(centre, extent, size, len(xy) * res * res, min(width, size), axis)
