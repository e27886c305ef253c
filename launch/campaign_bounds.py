"""A campaign's bounds on a cell's robot time (:mod:`launch.campaign`), pure maths: the **lower bound** (the dirt
area swept by the pad's long side at the speed limit plus the stains' minimum spanning tree at that speed) and the
**cell bound** (the run's fixed moves as executed, plus the sliding the felt needs under the sim's removal law and
the spanning tree, at the planner's speed bound)."""

from __future__ import annotations

import math

import numpy as np

from .campaign_cells import CampaignError


def mst_length_m(points: np.ndarray) -> float:
    """Length [m] of the minimum spanning tree of ``points`` (n, 2) (Prim; 0 for fewer than two)."""
    n = len(points)
    if n < 2:
        return 0.0
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    inside = np.zeros(n, bool)
    inside[0] = True
    best = d[0].copy()
    total = 0.0
    for _ in range(n - 1):
        best[inside] = np.inf
        j = int(np.argmin(best))
        total += float(best[j])
        inside[j] = True
        best = np.minimum(best, d[j])
    return total


def lower_bound_s(areas_m2: list[float], centres_m: np.ndarray, pad_width_m: float, speed_m_s: float) -> float:
    """A robot time [s] no run can beat: ``sum(area) / (pad_width v) + MST(centres) / v``.

    areas_m2 : dirt area of each stain [m^2]; centres_m : (n, 2) their centres on the board [m];
    pad_width_m : the pad's longest side [m] (the widest swath it can sweep); speed_m_s : the
    Cartesian speed limit [m/s]. Approach, retreat and force ramps only add to a real run.
    """
    if pad_width_m <= 0 or speed_m_s <= 0:
        raise CampaignError(f"pad width and speed must be > 0, got {pad_width_m}, {speed_m_s}")
    return float(sum(areas_m2)) / (pad_width_m * speed_m_s) + mst_length_m(np.asarray(centres_m, float)) / speed_m_s


def felt_path_m(area_m2: float, pad_area_m2: float, rate_per_n_m: float, force_over_threshold_n: float,
                level: float) -> float:
    """The shortest path [m] the pad must slide to bring a stain of ``area_m2`` down to ``level`` under the sim's
    removal law ``d <- d exp(-k (F - F0) ds)``: every point needs ``L = ln(1 / level) / (k (F - F0))`` of sliding
    under it, and a metre of path slides the pad's area over at most ``pad_area_m2``: ``L max(1, A / a_pad)``."""
    if min(pad_area_m2, rate_per_n_m, force_over_threshold_n) <= 0 or not 0 < level < 1:
        raise CampaignError("felt_path_m needs a positive pad area, rate and force over the threshold, level in (0, 1)")
    slide = math.log(1.0 / level) / (rate_per_n_m * force_over_threshold_n)
    return slide * max(1.0, area_m2 / pad_area_m2)


def cell_bound_s(fixed_moves_s: float, areas_m2: list[float], centres_m: np.ndarray, felt: dict[str, float],
                 speed_m_s: float) -> float:
    """The cell bound [s]: the run's fixed moves (before the skill's start + the final RETREAT, as executed) + each
    stain's :func:`felt_path_m` + the stains' minimum spanning tree, both at ``speed_m_s``. ``felt``: ``pad_area_m2``,
    ``rate_per_n_m``, ``force_over_threshold_n``, ``level``."""
    wipe = sum(felt_path_m(a, **felt) for a in areas_m2)
    return fixed_moves_s + (wipe + mst_length_m(np.asarray(centres_m, float))) / speed_m_s
