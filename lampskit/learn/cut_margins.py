"""How sure the segmentation is of each cut: a margin per boundary between two segments, so a user knows which
cut to check (``lamps segment --json`` writes them; docs/method.md argues them).

Two kinds of evidence, each as the natural log of a ratio to the level at which it alone decides (positive:
the cut is made by that much; near 0: a coin toss):

* **reachability** (the paper's OPTICS plot): the periodic side's kept points lie in a valley, the
  transitional side's on a peak; ``valley = log(threshold / median reachability of the periodic side)``,
  ``peak = log(median reachability of the transitional side / threshold)``; the cut's reachability margin is
  the smaller of the two (both must hold);
* **phase continuity** (:mod:`.phase_continuity`), for a transitional segment between two periodic ones: the
  lift, jump, period and pause ratios of the gap; its margin is the log of the largest.

A boundary's ``margin`` is the larger of its two margins, ``evidence`` names the one that gives it.
"""

from __future__ import annotations

import numpy as np

from lampskit.learn.phase_continuity import gap_evidence
from lampskit.learn.reachability import smooth_positions
from lampskit.learn.time_runs import REST_SPEED_SHARE, period_samples


def cut_margins(smooth: np.ndarray, rate_hz: float, t_s: np.ndarray, segments: list[tuple[str, int, int]],
                point_samples: np.ndarray, reachability: np.ndarray | None, threshold: float | None) -> list[dict]:
    """One dict per boundary between consecutive ``segments`` (``(kind, start, end)`` in time order).

    Parameters
    ----------
    smooth : array, shape (T, 3)
        Smoothed positions [m].
    rate_hz : float
        Mean sample rate [Hz].
    t_s : array, shape (T,)
        Sample times [s].
    point_samples : array of int, shape (M,)
        Sample index of each clustered point.
    reachability : array, shape (M,) or None
        Each point's OPTICS reachability [m] (None: no OPTICS, no reachability evidence).
    threshold : float or None
        The reachability threshold [m].

    Returns dicts with ``sample`` (first sample of the right segment), ``t_s``, ``left`` and ``right`` kinds,
    ``margin``, ``evidence`` and the parts that went into it (``valley``, ``peak``; ``lift``, ``jump``,
    ``period``, ``pause``).
    """
    velocity = smooth_positions(smooth, rate_hz, deriv=1)
    speed = np.linalg.norm(velocity, axis=1)
    out = []
    for k in range(1, len(segments)):
        (kl, al, bl), (kr, ar, br) = segments[k - 1], segments[k]
        cut: dict = {"sample": int(ar), "t_s": float(t_s[ar]), "left": kl, "right": kr}
        if reachability is not None and threshold and kl != kr:
            per, trans = ((al, bl), (ar, br)) if kl == "periodic" else ((ar, br), (al, bl))
            valley = _log_ratio(threshold, _median_reach(point_samples, reachability, *per))
            peak = _log_ratio(_median_reach(point_samples, reachability, *trans), threshold)
            cut.update(valley=valley, peak=peak)
        out.append(cut)
    # a transitional segment between two periodic ones: the phase-continuity evidence of its gap
    for k in range(1, len(segments) - 1):
        (kp, ap, bp), (kt, _, _), (kn, an, bn) = segments[k - 1], segments[k], segments[k + 1]
        if not (kp == kn == "periodic" and kt == "transitional"):
            continue
        lo, hi = ap, bn
        local = speed[lo:hi]
        rest = local < REST_SPEED_SHARE * float(np.median(speed[ap:bp].tolist() + speed[an:bn].tolist()))
        sides = (period_samples(velocity[ap:bp], rate_hz), period_samples(velocity[an:bn], rate_hz))
        period = int(np.median([p for p in sides if p])) if any(sides) else max(2, int(rate_hz))
        ev = gap_evidence(smooth[lo:hi], rest, (0, bp - lo), (an - lo, hi - lo), period, rate_hz, sides)
        parts = {"lift": ev.lift, "jump": ev.jump, "period": ev.period, "pause": ev.pause}
        for cut in (out[k - 1], out[k]):
            cut.update({name: float(v) for name, v in parts.items()})
            cut["continuity"] = ev.margin
    for cut in out:
        candidates = [(cut["continuity"], "continuity")] if "continuity" in cut else []
        if "valley" in cut:
            candidates.append((min(cut["valley"], cut["peak"]), "reachability"))
        candidates = [(m, name) for m, name in candidates if np.isfinite(m)]
        margin, evidence = max(candidates) if candidates else (None, "none")
        cut["margin"], cut["evidence"] = margin, evidence
        for name, value in cut.items():
            if isinstance(value, float) and not np.isfinite(value):
                cut[name] = None  # JSON has no NaN
    return out


def _median_reach(point_samples: np.ndarray, reachability: np.ndarray, a: int, b: int) -> float:
    inside = (point_samples >= a) & (point_samples < b)
    r = reachability[inside]
    r = r[np.isfinite(r)]
    return float(np.median(r)) if r.size else float("nan")


def _log_ratio(num: float, den: float) -> float:
    if not (np.isfinite(num) and np.isfinite(den)) or num <= 0 or den <= 0:
        return float("nan")
    return float(np.log(num / den))
