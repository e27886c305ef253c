"""The report's pure maths on a run's recorded series (no I/O): the controller trace's MP junction steps, motion
peaks, phase times, skill start and job end, the force as the cap watch sees it, and the dirt removed in the truth."""

from __future__ import annotations

import numpy as np

from controller.control.force import NormalForceRegulator
from controller.core import PHASE_CODES
from interfaces.messages import Phase

#: The phase codes (the controller trace's ``phase`` column) of the skill itself: wiping and the moves between strokes.
WIPING = (PHASE_CODES[Phase.WIPE], PHASE_CODES[Phase.TRANSITION])


#: A tick whose time scale departs this far from the mean of its neighbours' was one the robot held (the override
#: itself changes smoothly, within the planner's jerk bound).
HELD_SCALE_DIP = 0.01


def junction_steps(tr: np.ndarray, col: dict[str, int], window: int = 5) -> tuple[float, float]:
    """(largest one-tick reference-acceleration change at an MP junction [m/s^2], its ratio to the ticks around).

    The trace's accelerations are executed (time-scaled, x scale^2); a junction with a tick the robot held within
    ``window`` ticks is left out: that tick's scale follows the arm, not the skill, and its step is not the
    junction's (a held tick at 0.94 on a junction read as 3.8x an ordinary tick)."""
    if len(tr) < 3:
        return 0.0, 0.0
    phase = tr[:, col["phase"]]
    a = tr[:, [col["ref_ax"], col["ref_ay"]]]
    steps = np.linalg.norm(np.diff(a, axis=0), axis=1)  # steps[k] = a[k+1] - a[k]
    scale = tr[:, col["speed_scale"]]
    held = np.zeros(len(tr), bool)
    held[1:-1] = np.abs(scale[1:-1] - 0.5 * (scale[:-2] + scale[2:])) > HELD_SCALE_DIP
    chain = set(WIPING)
    js = [k for k in range(1, len(tr)) if phase[k] != phase[k - 1] and phase[k - 1] in chain
          and (phase[k] in chain or phase[k] == PHASE_CODES[Phase.RETREAT])
          and not held[max(k - 2 - window, 0): k + 2 + window].any()]
    worst, ratio = 0.0, 0.0
    for j in js:
        at = steps[max(j - 2, 0): j + 1]  # the change lands within a tick of the phase flag
        around = np.concatenate([steps[max(j - 2 - window, 0): max(j - 2, 0)], steps[j + 1: j + 1 + window]])
        jump = float(at.max())
        worst = max(worst, jump)
        ratio = max(ratio, jump / max(float(around.max()) if around.size else 0.0, 1e-9))
    return worst, ratio


def dirt_removed(truth: list[dict]) -> float:
    """1 - last / first total dirt of ``sim/truth`` (0 without truth or dirt)."""
    return (1.0 - truth[-1]["total_dirt"] / truth[0]["total_dirt"]) if truth and truth[0]["total_dirt"] > 0 else 0.0


def cap_watch_force(t_s: np.ndarray, force_n: np.ndarray, filter_s: float) -> np.ndarray:
    """The measured normal force as the controller's cap watch sees it: low-passed tick by tick.

    t_s, force_n : arrays, shape (n_ticks,), robot time [s] and measured normal force [N] of the trace.
    Returns an array, shape (n_ticks,) [N]. The filter is the controller's own
    (:meth:`NormalForceRegulator.measure`); where the robot clock goes back (a restarted controller) it
    starts again from 0 N, as the new controller's does; a gap is bridged with its real length.
    """
    watch = NormalForceRegulator(0.0, 0.0, 0.0, 1.0, filter_s)
    out = np.empty(len(force_n))
    prev = -np.inf
    for k, (t, f) in enumerate(zip(t_s.tolist(), force_n.tolist())):
        if t < prev:
            watch.filtered_n = 0.0
        out[k] = watch.measure(f, t - prev if np.isfinite(prev) and t > prev else 0.0)
        prev = t
    return out


def motion_peaks(tr: np.ndarray, col: dict[str, int]) -> dict[str, dict[str, float]]:
    """Peak speed, acceleration and jerk of the executed in-plane reference per phase name and over ``all``."""
    if len(tr) < 2:
        return {}
    t, phase = tr[:, col["t_s"]], tr[:, col["phase"]]
    v = np.linalg.norm(tr[:, [col["ref_vx"], col["ref_vy"]]], axis=1)
    a_xy = tr[:, [col["ref_ax"], col["ref_ay"]]]
    a = np.linalg.norm(a_xy, axis=1)
    dt = np.diff(t)
    tick = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.0
    consecutive = (dt > 0) & (dt <= 1.5 * tick) & (phase[1:] == phase[:-1])
    jerk = np.zeros(len(tr))
    jerk[1:][consecutive] = np.linalg.norm(np.diff(a_xy, axis=0)[consecutive], axis=1) / dt[consecutive]
    names = {code: name for name, code in PHASE_CODES.items()}
    out = {}
    for code in [None, *sorted(set(phase.astype(int).tolist()))]:
        sel = np.ones(len(tr), bool) if code is None else phase == code
        out["all" if code is None else names.get(code, str(code))] = {
            "speed_m_s": float(v[sel].max()), "accel_m_s2": float(a[sel].max()), "jerk_m_s3": float(jerk[sel].max()),
            "ticks": int(np.count_nonzero(sel))}
    return out


def phase_times(tr: np.ndarray, col: dict[str, int]) -> dict[str, float]:
    """Robot time [s] per phase name and ``all``: each interval between consecutive recorded ticks (at most 1.5
    ordinary ticks apart: a gap is nobody's) counts for the phase of its first tick."""
    if len(tr) < 2:
        return {}
    t, phase = tr[:, col["t_s"]], tr[:, col["phase"]].astype(int)
    dt = np.diff(t)
    tick = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.0
    dt = np.where((dt > 0) & (dt <= 1.5 * tick), dt, 0.0)
    names = {code: name for name, code in PHASE_CODES.items()}
    out = {names.get(c, str(c)): float(dt[phase[:-1] == c].sum()) for c in sorted(set(phase[:-1].tolist()))}
    out["all"] = float(dt.sum())
    return out


def skill_start(tr: np.ndarray, col: dict[str, int]) -> float | None:
    """Robot time [s] of the first recorded TRANSITION or WIPE tick (None if there is none)."""
    if not len(tr):
        return None
    hit = np.flatnonzero(np.isin(tr[:, col["phase"]].astype(int), WIPING))
    return float(tr[hit[0], col["t_s"]]) if hit.size else None


def job_end(tr: np.ndarray, col: dict[str, int]) -> float | None:
    """Robot time [s] of the first tick of the DONE the recording ends in (None if it does not end DONE)."""
    if not len(tr):
        return None
    done = tr[:, col["phase"]].astype(int) == PHASE_CODES[Phase.DONE]
    if not done[-1]:
        return None
    other = np.flatnonzero(~done)
    return float(tr[other[-1] + 1 if other.size else 0, col["t_s"]])


def final_retreat(tr: np.ndarray, col: dict[str, int]) -> float | None:
    """Robot time [s] of the RETREAT that ends in the DONE the recording ends in (from its first tick to that
    DONE; None if it does not end DONE after a RETREAT). Retreats before it (a look, then a re-pass) are not it."""
    end = job_end(tr, col)
    if end is None:
        return None
    t, phase = tr[:, col["t_s"]], tr[:, col["phase"]].astype(int)
    before = np.flatnonzero(t < end)
    if not before.size or phase[before[-1]] != PHASE_CODES[Phase.RETREAT]:
        return None
    other = np.flatnonzero(phase[: before[-1] + 1] != PHASE_CODES[Phase.RETREAT])
    return float(end - t[other[-1] + 1 if other.size else 0])
