"""Step 6's cut decision: is a stretch that does not recur, between two recurring ones, a break between two
wiping phases or a slow stretch inside one?

The recurrence of step 6 (:func:`lampskit.learn.time_runs.recurrence`) marks every sample that does not repeat
the path one period earlier or later. Inside one wiping phase a person does that often: a stroke two or three
times slower than the rest, a pause at a turning point, a centre that drifts as the stain shrinks. Between two
phases the tool leaves: it lifts off, or moves to another patch. Time alone cannot tell the two apart (a slow
stroke lasts as long as a quick hop), so :func:`gap_evidence` measures what survives a person's mess, each as a
ratio to the level at which it alone makes the cut (a ratio above 1 cuts):

``lift``
    the highest the tool stays for :data:`~lampskit.learn.contact.LIFT_MIN_S` in the gap above the surface the
    strokes on both sides span (a plane through their samples), over that surface's contact band
    (:func:`~lampskit.learn.contact.contact_band` of the strokes' own heights plus
    :data:`~lampskit.learn.contact.LIFT_MARGIN_M`, at least :data:`MIN_LIFT_M`): a hop leaves the surface, a slow
    stroke does not;
``jump``
    the in-plane distance between the centres of the strokes before and after (the middle of the box they span
    over :data:`CONTEXT_PERIODS` periods, wherever in a stroke the gap starts), over :data:`JUMP_SHARE` of the
    strokes' reach (the 95th percentile of their in-plane distance from their centre) plus the drift
    :data:`DRIFT_M_S` allows over the gap's duration: a drift moves the centre a few millimetres per stroke, a
    move to the next patch by about a pad length within a second or two;
``period``
    the larger over the smaller of the stroke periods either side, over :data:`PERIOD_RATIO` (when both sides
    hold :data:`PERIOD_SIDE_PERIODS` periods): the same strokes continue at the same frequency after a slow
    stretch;
``pause``
    the time at rest in the gap over :data:`PAUSE_MAX_S` (a person stops at a turning point for well under a
    second and goes on; a longer stop is the end of a phase).

The gap is a cut when any ratio exceeds 1; its margin is the log of the largest ratio (negative: the phase
holds, by that much). On the OPTICS reachability plot the same reading is made: a valley is a place passed
again and again, and two valleys joined below the threshold are one region; this step only decides whether the
times the region was passed belong to one phase of work.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import minimum_filter1d

from lampskit.learn.contact import LIFT_MARGIN_M, LIFT_MIN_S, contact_band

#: A centre jump of this share of the strokes' reach cuts.
JUMP_SHARE = 1.0
#: ... plus the drift a stroke centre may make while the gap lasts, at this speed [m/s] (a shrinking stain's
#: strokes drift about 2 mm/s: 5 cm over 27 s).
DRIFT_M_S = 0.005
#: Stroke periods either side differing by this factor cut.
PERIOD_RATIO = 3.0
#: ... read only when both sides recur for this many periods (a shorter window's autocorrelation finds a half
#: period as readily as the period).
PERIOD_SIDE_PERIODS = 3.0
#: A rest longer than this [s] inside the gap cuts.
PAUSE_MAX_S = 1.5
#: A lift is at least this high [m] whatever the contact band (a hop lifts 2-8 cm; a grater's or a line
#: stroke's plane is poorly defined across the line, and a hand wanders a centimetre off it).
MIN_LIFT_M = 0.015
#: The strokes either side are read over this many periods.
CONTEXT_PERIODS = 2.0


@dataclass(frozen=True)
class GapEvidence:
    """Ratios (module docstring) of one gap; ``margin`` = log of the largest, ``reason`` its name."""

    lift: float
    jump: float
    period: float
    pause: float

    @property
    def reason(self) -> str:
        return max(("lift", "jump", "period", "pause"), key=lambda k: getattr(self, k))

    @property
    def margin(self) -> float:
        return float(np.log(max(getattr(self, self.reason), 1e-9)))

    @property
    def cuts(self) -> bool:
        return self.margin > 0.0


def gap_evidence(points: np.ndarray, rest: np.ndarray, before: tuple[int, int],
                 after: tuple[int, int], period: int, rate_hz: float,
                 periods: tuple[int | None, int | None] = (None, None)) -> GapEvidence:
    """Evidence for a cut in the gap ``[before[1], after[0])`` between two recurring stretches.

    Parameters
    ----------
    points : array, shape (K, 3)
        Smoothed positions [m].
    rest : array of bool, shape (K,)
        Samples at rest (slower than the run's rest speed).
    before, after : (int, int)
        The recurring stretches ``[start, end)`` on either side.
    period : int
        The run's stroke period [samples].
    rate_hz : float
        Sample rate [Hz].
    periods : (int or None, int or None)
        Each side's own stroke period [samples], if known.
    """
    w = max(3, int(CONTEXT_PERIODS * period))
    sa = points[max(before[0], before[1] - w):before[1]]
    sb = points[after[0]:min(after[1], after[0] + w)]
    gap = points[before[1]:after[0]]
    strokes = np.vstack([sa, sb])
    centre = strokes.mean(axis=0)
    _, _, vt = np.linalg.svd(strokes - centre, full_matrices=False)
    normal = vt[2]
    h_strokes = (strokes - centre) @ normal
    h_gap = (gap - centre) @ normal
    band = max(contact_band(h_strokes) + LIFT_MARGIN_M, MIN_LIFT_M)
    n_min = max(1, int(LIFT_MIN_S * rate_hz))
    # the height the pad holds for LIFT_MIN_S at least (a spike or a wobble off a line stroke's plane is no lift)
    held = minimum_filter1d(np.abs(h_gap), n_min, mode="nearest") if len(h_gap) >= n_min else np.zeros(1)
    lift = float(np.max(held)) / band
    ca, cb = _midrange(sa, vt[:2]), _midrange(sb, vt[:2])
    reach = max(float(np.percentile(np.linalg.norm((sa - ca) @ vt[:2].T, axis=1), 95)),
                float(np.percentile(np.linalg.norm((sb - cb) @ vt[:2].T, axis=1), 95)), 1e-6)
    gap_s = (after[0] - before[1]) / rate_hz
    jump = float(np.linalg.norm((cb - ca) @ vt[:2].T)) / (JUMP_SHARE * reach + DRIFT_M_S * gap_s)
    pa, pb = periods
    long_enough = min(before[1] - before[0], after[1] - after[0]) >= PERIOD_SIDE_PERIODS * period
    ratio = max(pa, pb) / min(pa, pb) if pa and pb and long_enough else 1.0
    pause = float(_longest_run(rest[before[1]:after[0]])) / rate_hz / PAUSE_MAX_S
    return GapEvidence(lift, jump, ratio / PERIOD_RATIO, pause)


def _midrange(points: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The centre (3,) of the box of ``points`` (K, 3) along the in-plane ``axes`` (2, 3): a stroke's centre
    whatever share of a cycle the window holds (a window's mean is pulled toward the part of a stroke it
    holds twice)."""
    proj = points @ axes.T
    mid = 0.5 * (proj.min(axis=0) + proj.max(axis=0))
    mean = points.mean(axis=0)
    return mean + (mid - mean @ axes.T) @ axes


def _longest_run(mask: np.ndarray) -> int:
    if not mask.any():
        return 0
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return int(np.max(edges[1::2] - edges[::2]))
