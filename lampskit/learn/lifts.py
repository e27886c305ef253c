"""Step 5b of the segmentation: a periodic run is cut where the tool hops off the surface between two wipes.

A person often lifts the pad a few centimetres, moves it about a pad length to the next patch and wipes
again, all within one to three seconds. The two patches overlap or nearly touch, so OPTICS sees one dense
region and, with the stroke periods of both wipes in one run, the recurrence of step 6 neither finds one
period nor a non-recurring gap long enough to split at. What marks the hop is the height: the pad leaves the
surface it wipes on. :func:`split_at_lifts` cuts a periodic run ``(cluster, start, end)`` wherever

1. the tool stands higher than the *contact band* above the run's own surface: a plane fitted to the run's
   samples (refitted to the samples within :data:`PLANE_KEEP` times the median distance from it, so a hop's
   samples do not tilt it), with the band :data:`~.contact.BAND_FACTOR` times that median distance (at least
   :data:`~.contact.BAND_MIN_M`) plus :data:`~.contact.LIFT_MARGIN_M`, on the side the tool comes from (the side
   most of the whole demo lies on: approaches and retracts);
2. for at least :data:`~.contact.LIFT_MIN_S`, with at least :data:`SIDE_MIN_S` of the run in contact on each side (a
   lift at a run's end is its approach or retract, which step 6 trims);
3. and the motion there does not recur: its median recurrence (step 6's, at the period of the strokes just
   before it, or just after) is at least :data:`~.time_runs.REC_GAMMA` times the median of the strokes around
   it. A real wrist rises and falls with the strokes (the recordings' flange moves 2-4 cm off its plane in
   some cycles, for up to 0.8 s): that rise repeats the stroke and is no hop.

Each cut leaves the lifted stretch transitional; step 6 then moves both wipes' ends to where their own
strokes stop recurring, each with its own period. A stroke centre drifting while in contact never rises
off the band, so it is never cut here.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

from lampskit.learn.contact import LIFT_MARGIN_M, LIFT_MIN_S, contact_band
from lampskit.learn.reachability import smooth_positions
from lampskit.learn.time_runs import REC_GAMMA, REST_SPEED_SHARE, Run, period_samples, recurrence, runs_from_labels

#: The surface is first placed through this lower share of a run's samples.
PLANE_KEEP = 0.5
#: A lift this long [s] is a hop whatever the strokes around it do (the recordings' flange rises with a
#: stroke for 0.5 s at most; a 1 s hop of 2 cm stays above 1 cm for 0.7 s).
LIFT_SURE_S = 0.6
#: Each side of a cut keeps at least this much contact within the run [s].
SIDE_MIN_S = 0.5
#: The strokes around a lift whose recurrence it is compared with: this long on each side [s].
CONTEXT_S = 3.0


def heights(points: np.ndarray, velocity: np.ndarray, all_points: np.ndarray) -> np.ndarray:
    """Signed height (K,) [m] of ``points`` (K, 3) above the surface they are wiped on, positive toward
    ``all_points``' side (M, 3) (where approaches and retracts are).

    The normal is the least-variance direction of the velocities ``velocity`` (K, 3) [m/s]: the strokes are
    fast and run along the surface. (A run holding wipes and hops spans a few centimetres of height over a
    patch of board not much wider, so the positions' least-variance direction need not be the normal.) The
    surface passes through the lower :data:`PLANE_KEEP` share of the samples (a hop's and an approach's
    samples are high, and take less than half of a run), then through every sample within its contact band.
    """
    normal = np.linalg.svd(velocity, full_matrices=False)[2][2]
    h = points @ normal
    if float(np.mean(all_points @ normal)) < float(np.mean(h)):
        normal, h = -normal, -h
    h = h - float(np.mean(h[h <= np.quantile(h, PLANE_KEEP)]))
    return h - float(np.mean(h[np.abs(h) <= contact_band(h)]))


def lifted_stretches(h: np.ndarray, rate_hz: float) -> list[tuple[int, int]]:
    """Stretches ``(start, end)`` of ``h`` (K,) [m] above the contact band for at least :data:`~.contact.LIFT_MIN_S`."""
    up = (h > contact_band(h) + LIFT_MARGIN_M).astype(int)
    return [(a, b) for v, a, b in runs_from_labels(up) if v == 1 and b - a >= LIFT_MIN_S * rate_hz] if len(h) else []


def split_at_lifts(runs: list[Run], smooth: np.ndarray, rate_hz: float) -> list[Run]:
    """Cut periodic runs where the tool hops off the surface (module docstring); other runs are left alone."""
    out: list[Run] = []
    velocity = smooth_positions(smooth, rate_hz, deriv=1)
    side = int(SIDE_MIN_S * rate_hz)
    for c, a, b in runs:
        cuts = []
        if c >= 0 and b - a > 2 * side:
            for l0, l1 in lifted_stretches(heights(smooth[a:b], velocity[a:b], smooth), rate_hz):
                if l0 < side or l1 > b - a - side:
                    continue
                if l1 - l0 >= LIFT_SURE_S * rate_hz or not _recurs(smooth, velocity, rate_hz, a, b, a + l0, a + l1):
                    cuts.append((a + l0, a + l1))
        start = a
        for l0, l1 in cuts:
            out.extend([(c, start, l0), (-1, l0, l1)])
            start = l1
        out.append((c, start, b))
    return out


def _recurs(smooth: np.ndarray, velocity: np.ndarray, rate_hz: float, a: int, b: int, l0: int, l1: int) -> bool:
    """Whether the lifted stretch ``[l0, l1)`` of the run ``[a, b)`` repeats the strokes just before or after it
    (each side at its own period: two wipes need not share one)."""
    w = int(CONTEXT_S * rate_hz)
    for lo, hi, side in ((max(a, l0 - w), l1, slice(0, l0 - max(a, l0 - w))),
                         (l0, min(b, l1 + w), slice(l1 - l0, min(b, l1 + w) - l0))):
        period = period_samples(velocity[lo:hi][side], rate_hz)
        if period is None:
            continue
        omega = 2 * np.pi * rate_hz / period
        rec = recurrence(np.hstack([smooth[lo:hi], velocity[lo:hi] / omega]), period)
        finite = np.isfinite(rec)
        if not finite[side].any():
            continue
        rec[~finite] = np.max(rec[finite])
        speed = np.linalg.norm(velocity[lo:hi], axis=1)
        rec[speed < REST_SPEED_SHARE * float(np.median(speed[side]))] = np.max(rec)
        rec = median_filter(rec, size=max(1, period // 2) | 1, mode="nearest")
        lift = slice(l0 - lo, l1 - lo)
        if float(np.median(rec[lift])) < REC_GAMMA * float(np.median(rec[side])):
            return True
    return False
