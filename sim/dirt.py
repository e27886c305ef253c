"""Dirt on the board: a grid of cells in [0, 1], stains drawn into it, and the eraser's removal law.

Pure numpy, no PyBullet: the sim calls :meth:`DirtGrid.wipe` once per step
with the pad's pose, velocity and normal force expressed in the board frame.

Grid layout: ``dirt[iy, ix]`` covers the board-frame square
``[ix c, (ix + 1) c] x [iy c, (iy + 1) c]`` (c = cell size), so row 0 is
the board's bottom edge.

Removal law, for every cell whose centre lies under the pad while the
normal force F exceeds the threshold F0 and the pad is flat on the board::

    d <- d exp(-k (F - F0) ds),   ds = |v + omega x r| dt

with v the pad's sliding velocity in the board plane, omega its spin about
the normal and r the cell's offset from the pad centre: the rate grows with
force and with the distance slid over the cell; a pad pressed without
sliding removes nothing.

A stain may carry a ghost (``ghost`` g of a stain table: dried-in marker a
dry eraser smears but cannot lift): its cells keep ``g`` of their first
dirt, ``d <- g d0 + (d - g d0) exp(-k (F - F0) ds)``, however often they
are wiped (perception calls such a stain smeared, :mod:`perception.smear`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from interfaces.errors import ConfigError
from interfaces.stain_shape import Shape, shape_of


@dataclass(frozen=True)
class StainShape:
    """One stain: ``centre_m`` (2,) board frame, ``size_m`` larger extent, ``aspect`` >= 1, ``angle_rad`` of its long
    axis; ``ghost``: the fraction of its dirt the eraser cannot lift."""

    id: int
    centre_m: tuple[float, float]
    size_m: float
    aspect: float = 1.3
    angle_rad: float = 0.0
    wobble_seed: int = 0
    ghost: float = 0.0


def random_stains(rng: np.random.Generator, count: int, size_range_m: tuple[float, float],
                  lo: np.ndarray, hi: np.ndarray, max_tries: int = 2000) -> list[StainShape]:
    """``count`` non-overlapping stains with centres in the box ``lo``-``hi`` (2,) [m], sizes in ``size_range_m``.

    Stains keep 3 cm of clean board between them, so each one is a separate
    cluster. Raises :class:`ConfigError` if they do not fit.
    """
    stains: list[StainShape] = []
    for _ in range(max_tries):
        if len(stains) == count:
            break
        size = float(rng.uniform(*size_range_m))
        centre = rng.uniform(lo + size / 2, hi - size / 2) if np.all(hi - lo > size) else (lo + hi) / 2
        if all(math.dist(centre, s.centre_m) > (size + s.size_m) / 2 + 0.03 for s in stains):
            stains.append(StainShape(len(stains), (float(centre[0]), float(centre[1])), size,
                                     float(rng.uniform(1.0, 1.8)), float(rng.uniform(0, math.pi)),
                                     int(rng.integers(2**31))))
    if len(stains) < count:
        raise ConfigError(f"{count} stains of {size_range_m} m do not fit on the board's stain region "
                          f"{np.round(lo, 3).tolist()}-{np.round(hi, 3).tolist()} m")
    return stains


def stains_from_specs(specs: Sequence[Mapping[str, Any]], lo: np.ndarray, hi: np.ndarray) -> list[StainShape]:
    """Stains from config tables ``{centre_m = [x, y], size_m = s, aspect = a, angle_deg = t, ghost = g}``."""
    out = []
    for i, spec in enumerate(specs):
        unknown = sorted(set(spec) - {"centre_m", "size_m", "aspect", "angle_deg", "ghost"})
        if unknown:
            raise ConfigError(f"[sim.dirt] stain {i}: unknown key(s) {unknown}; valid: centre_m, size_m, aspect, "
                              "angle_deg, ghost")
        try:
            centre = np.array(spec["centre_m"], float).reshape(2)
            size = float(spec["size_m"])
            aspect = float(spec.get("aspect", 1.3))
            angle = math.radians(float(spec.get("angle_deg", 0.0)))
            ghost = float(spec.get("ghost", 0.0))
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise ConfigError(f"[sim.dirt] stain {i} needs centre_m = [x, y] and size_m (numbers): {exc}") from None
        if not (0.01 <= size <= 0.3 and 1.0 <= aspect <= 4.0 and np.all(np.isfinite(centre)) and math.isfinite(angle)):
            raise ConfigError(f"[sim.dirt] stain {i}: size_m must be in [0.01, 0.3], aspect in [1, 4], "
                              "centre_m and angle_deg finite")
        if not 0.0 <= ghost <= 0.95:
            raise ConfigError(f"[sim.dirt] stain {i}: ghost must be in [0, 0.95] (the fraction the eraser cannot "
                              f"lift), got {spec.get('ghost')!r}")
        if np.any(centre < lo) or np.any(centre > hi):
            raise ConfigError(f"[sim.dirt] stain {i}: centre {centre.tolist()} m is outside the stain region "
                              f"{np.round(lo, 3).tolist()}-{np.round(hi, 3).tolist()} m")
        out.append(StainShape(i, (float(centre[0]), float(centre[1])), size, aspect, angle, 1000 + i, ghost))
    return out


def _stain_mask(shape: StainShape, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Boolean mask over the cell centres ``xs`` (nx,), ``ys`` (ny,): an ellipse with a wobbly edge."""
    rng = np.random.default_rng(shape.wobble_seed)
    a = shape.size_m / 2
    b = a / shape.aspect
    dx = xs[None, :] - shape.centre_m[0]
    dy = ys[:, None] - shape.centre_m[1]
    c, s = math.cos(shape.angle_rad), math.sin(shape.angle_rad)
    u, v = c * dx + s * dy, -s * dx + c * dy
    theta = np.arctan2(v / b, u / a)
    wobble = 1.0 + sum(rng.uniform(0.03, 0.10) * np.cos(k * theta + rng.uniform(0, 2 * np.pi)) for k in (2, 3, 5))
    return (u / a) ** 2 + (v / b) ** 2 <= (wobble / 1.1) ** 2


class DirtGrid:
    """The board's dirt, its stains' labels and the removal law.

    Attributes
    ----------
    dirt : array, shape (ny, nx), float32 in [0, 1]
    labels : array, shape (ny, nx), int16, stain id or -1
    cell_m : float, cell size [m]
    """

    def __init__(self, board_size_m: np.ndarray, cell_m: float, stains: Sequence[StainShape], seed: int = 0) -> None:
        self.cell_m = float(cell_m)
        self.nx = int(round(board_size_m[0] / cell_m))
        self.ny = int(round(board_size_m[1] / cell_m))
        self.stains = list(stains)
        xs = (np.arange(self.nx) + 0.5) * cell_m
        ys = (np.arange(self.ny) + 0.5) * cell_m
        self.dirt = np.zeros((self.ny, self.nx), np.float32)
        self.labels = np.full((self.ny, self.nx), -1, np.int16)
        rng = np.random.default_rng(seed)
        for shape in self.stains:
            mask = _stain_mask(shape, xs, ys)
            self.labels[mask] = shape.id
            self.dirt[mask] = rng.uniform(0.75, 1.0, int(mask.sum())).astype(np.float32)
        #: what the eraser cannot lift (None: nothing, the common case, and the cheaper wipe)
        self._floor: np.ndarray | None = None
        if any(s.ghost > 0.0 for s in self.stains):
            ghost = np.zeros(max(s.id for s in self.stains) + 2, np.float32)  # index -1 (no stain) reads 0
            for s in self.stains:
                ghost[s.id] = s.ghost
            self._floor = self.dirt * ghost[self.labels]
        self._index = [np.flatnonzero(self.labels.ravel() == s.id) for s in self.stains]
        self._initial = np.array([self.dirt.ravel()[i].sum() for i in self._index], float)
        self.version = 0

    def shapes(self) -> list[Shape]:
        """The drawn stains' true centres and sizes (:mod:`interfaces.stain_shape`), in stain order."""
        out = []
        for index in self._index:
            iy, ix = np.divmod(index, self.nx)
            out.append(shape_of(np.column_stack([(ix + 0.5) * self.cell_m, (iy + 0.5) * self.cell_m]), self.cell_m))
        return out

    @property
    def stain_ids(self) -> list[int]:
        return [s.id for s in self.stains]

    def remaining(self) -> np.ndarray:
        """(k,) dirt left on each stain relative to its start, in [0, 1]."""
        flat = self.dirt.ravel()
        return np.array([flat[i].sum() / max(init, 1e-12) for i, init in zip(self._index, self._initial)])

    def total(self) -> float:
        """Sum of the grid [cell units]."""
        return float(self.dirt.sum(dtype=np.float64))

    def wipe(self, centre_m: np.ndarray, axis: np.ndarray, half_size_m: tuple[float, float],
             velocity_m_s: np.ndarray, spin_rad_s: float, force_n: float, dt_s: float,
             threshold_force_n: float, rate_per_n_m: float) -> int:
        """Remove dirt under the pad for one step; returns the number of cells covered.

        centre_m (2,), axis (2,) unit vector of the pad's long side,
        velocity_m_s (2,): all in the board frame; half_size_m: pad half
        length and half width [m]; spin_rad_s: pad spin about the board
        normal; force_n: normal force pressing the pad on the board.
        """
        excess = force_n - threshold_force_n
        if excess <= 0.0:
            return 0
        c = self.cell_m
        a, b = half_size_m
        reach_x = abs(a * axis[0]) + abs(b * axis[1])  # half extents of the pad's bounding box
        reach_y = abs(a * axis[1]) + abs(b * axis[0])
        ix0 = max(int((centre_m[0] - reach_x) / c), 0)
        ix1 = min(int((centre_m[0] + reach_x) / c) + 1, self.nx)
        iy0 = max(int((centre_m[1] - reach_y) / c), 0)
        iy1 = min(int((centre_m[1] + reach_y) / c) + 1, self.ny)
        if ix0 >= ix1 or iy0 >= iy1:
            return 0
        rx = (np.arange(ix0, ix1) + 0.5) * c - centre_m[0]
        ry = (np.arange(iy0, iy1) + 0.5) * c - centre_m[1]
        along = axis[0] * rx[None, :] + axis[1] * ry[:, None]
        across = -axis[1] * rx[None, :] + axis[0] * ry[:, None]
        inside = (np.abs(along) <= half_size_m[0]) & (np.abs(across) <= half_size_m[1])
        n = int(inside.sum())
        if n == 0:
            return 0
        vx = velocity_m_s[0] - spin_rad_s * ry[:, None]
        vy = velocity_m_s[1] + spin_rad_s * rx[None, :]
        ds = np.hypot(vx, vy) * dt_s
        window = self.dirt[iy0:iy1, ix0:ix1]
        lift = np.exp(-rate_per_n_m * excess * ds[inside]).astype(np.float32)
        if self._floor is None:
            window[inside] *= lift
        else:
            floor = self._floor[iy0:iy1, ix0:ix1][inside]
            window[inside] = floor + (window[inside] - floor) * lift
        self.version += 1
        return n
