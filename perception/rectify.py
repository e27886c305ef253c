"""The rectified board image: a grid of square pixels on the board plane, and the homography that fills it.

Grid pixel ``(row i, col j)`` covers the board-frame point
``x = (j + 1/2) r``, ``y = h - (i + 1/2) r`` (r = resolution, h = board
height): row 0 is the board's top edge, so the image looks like the board
seen from the front.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from interfaces.board_markers import DEFAULT_LAYOUT, MarkerLayout


@dataclass(frozen=True)
class BoardGrid:
    """The rectified image's geometry: ``size_m`` (w, h) of the board, ``resolution_m`` per pixel."""

    size_m: tuple[float, float]
    resolution_m: float

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        w, h = self.size_m
        return max(int(round(h / self.resolution_m)), 1), max(int(round(w / self.resolution_m)), 1)

    def board_from_grid(self) -> np.ndarray:
        """(3, 3) homogeneous map from grid pixel (col, row, 1) to board point (x, y, 1) [m]."""
        r, h = self.resolution_m, self.shape[0] * self.resolution_m
        return np.array([[r, 0.0, 0.5 * r], [0.0, -r, h - 0.5 * r], [0.0, 0.0, 1.0]])

    def xy_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Board-frame points (n, 2) [m] of grid pixels ``rows``, ``cols`` (n,)."""
        r = self.resolution_m
        return np.column_stack([(cols + 0.5) * r, self.shape[0] * r - (rows + 0.5) * r])

    def image_from_grid(self, K: np.ndarray, T_board_to_camera: np.ndarray) -> np.ndarray:
        """(3, 3) homography from grid pixel (col, row, 1) to camera pixel (u, v, 1)."""
        P = K @ T_board_to_camera[:3][:, [0, 1, 3]]  # board plane z = 0
        return P @ self.board_from_grid()

    def warp(self, rgb: np.ndarray, H_image_from_grid: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The rectified board image (rows, cols, 3) of ``rgb`` (bilinear; outside the camera image: 0)."""
        rows, cols = self.shape
        return cv2.warpPerspective(rgb, H_image_from_grid, (cols, rows), dst=out,
                                   flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT,
                                   borderValue=(0, 0, 0))

    def looked_at(self, edge_margin_m: float, marker_margin_m: float,
                  layout: MarkerLayout = DEFAULT_LAYOUT) -> np.ndarray:
        """(rows, cols) bool: board pixels perception judges (not the edge band, not the markers)."""
        rows, cols = self.shape
        mask = np.zeros((rows, cols), bool)
        e = int(np.ceil(edge_margin_m / self.resolution_m))
        mask[e:rows - e, e:cols - e] = True
        r = self.resolution_m
        side = layout.side_m
        for x0, y0 in layout.origins(self.size_m).values():
            c0 = int(np.floor((x0 - marker_margin_m) / r))
            c1 = int(np.ceil((x0 + side + marker_margin_m) / r))
            r0 = int(np.floor((self.shape[0] * r - (y0 + side + marker_margin_m)) / r))
            r1 = int(np.ceil((self.shape[0] * r - (y0 - marker_margin_m)) / r))
            mask[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = False
        return mask
