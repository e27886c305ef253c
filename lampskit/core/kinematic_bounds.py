"""The planner's kinematic bounds (point 4 of :mod:`lampskit.core.planner`): peak speed, acceleration and jerk of
a periodic MP's limit cycle and of a planned transition, the largest Omega that keeps a cycle within the bounds
and the shortest duration that keeps a transition within them. Pure maths on the closed forms."""

from __future__ import annotations

import numpy as np

from lampskit.core.periodic import periodic_state
from lampskit.core.planner_types import PlannerParams
from lampskit.core.transitional_plan import evaluate as evaluate_transition
from lampskit.core.transitional_plan import plan_transition as plan_transition_mp

#: A periodic MP is kept this far inside the bounds: a transition ends in its state, and needs some room.
PERIODIC_MARGIN = 0.85
#: Phases sampled on a limit cycle to find its peaks.
_CYCLE_SAMPLES = 720
#: A transition is planned to this share of the bounds: its sampled peaks miss a little between samples.
BOUND_SHARE = 0.97
#: Time step [s] at which a transition's closed form is sampled to find its peaks.
PEAK_DT_S = 0.004


def cycle_peaks(mp, amplitude_m: float, omega_rad_s: float) -> tuple[float, float, float]:
    """Peak speed, acceleration and jerk [m/s, m/s^2, m/s^3] on ``mp``'s limit cycle at that amplitude and
    frequency (closed form; jerk by a central difference of the acceleration in phase)."""
    phases = np.linspace(0.0, 2 * np.pi, _CYCLE_SAMPLES, endpoint=False)
    _, vel, acc = periodic_state(mp, phases, None, amplitude_m, omega_rad_s)
    dphi = phases[1] - phases[0]
    jerk = (np.roll(acc, -1, axis=0) - np.roll(acc, 1, axis=0)) / (2 * dphi) * omega_rad_s
    return (float(np.linalg.norm(vel, axis=1).max()), float(np.linalg.norm(acc, axis=1).max()),
            float(np.linalg.norm(jerk, axis=1).max()))


_UNIT_PEAKS: dict[int, tuple] = {}  # id(mp) -> (mp, its peaks at r = 1 m, Omega = 1 rad/s)


def unit_cycle_peaks(mp) -> tuple[float, float, float]:
    """:func:`cycle_peaks` at amplitude 1 m and Omega 1 rad/s, computed once per MP (the limit cycle scales
    linearly with r: peaks at r are r times these)."""
    hit = _UNIT_PEAKS.get(id(mp))
    if hit is None or hit[0] is not mp:  # the MP itself is kept, so its id is not reused meanwhile
        if len(_UNIT_PEAKS) > 256:
            _UNIT_PEAKS.clear()
        hit = _UNIT_PEAKS[id(mp)] = (mp, cycle_peaks(mp, 1.0, 1.0))
    return hit[1]


def bounded_omega(mp, amplitude_m: float, params: PlannerParams, share: float = 1.0) -> float:
    """The largest Omega [rad/s] at which ``mp``'s limit cycle of amplitude ``amplitude_m`` stays within
    ``share`` of the planner's bounds: speed scales with Omega, acceleration with its square, jerk with its
    cube, each linearly with the amplitude."""
    v1, a1, j1 = (amplitude_m * x for x in unit_cycle_peaks(mp))
    return float(min(share * params.max_speed_m_s / max(v1, 1e-12),
                     np.sqrt(share * params.max_accel_m_s2 / max(a1, 1e-12)),
                     np.cbrt(share * params.max_jerk_m_s3 / max(j1, 1e-12))))


def trajectory_peaks(tp) -> tuple[float, float, float]:
    """Peak speed, acceleration and jerk of a planned transition (``transitional_plan.TransitionPlan``), its
    closed form sampled every :data:`PEAK_DT_S` from start to end (jerk: differences of the acceleration)."""
    n = max(int(np.ceil(tp.duration_s / PEAK_DT_S)), 4)
    smp = evaluate_transition(tp, np.linspace(0.0, tp.duration_s, n + 1))
    jerk = np.diff(smp.acceleration_m_s2, axis=0) / (tp.duration_s / n)
    return (float(np.linalg.norm(smp.velocity_m_s, axis=1).max()),
            float(np.linalg.norm(smp.acceleration_m_s2, axis=1).max()), float(np.linalg.norm(jerk, axis=1).max()))


def bounded_duration(mp, start, goal, duration_s: float, transform: np.ndarray, params: PlannerParams
                     ) -> tuple[float, tuple[float, float, float], bool]:
    """(duration [s], its peaks, whether within the bounds) of a transition lengthened from ``duration_s`` until
    its peaks are within the planner's bounds, at most ``max_transition_stretch`` times.

    Stretching time by k divides the learned part's speed by k, acceleration by k^2, jerk by k^3; the
    boundary states do not scale, so each step re-evaluates (a few closed-form samplings, ~1 ms each).
    """
    T, longest = duration_s, duration_s * params.max_transition_stretch
    best: tuple[float, tuple[float, float, float], float] | None = None
    for _ in range(12):
        peaks = trajectory_peaks(plan_transition_mp(mp, start, goal, T, transform))
        excess = max(peaks[0] / params.max_speed_m_s, np.sqrt(peaks[1] / params.max_accel_m_s2),
                     np.cbrt(peaks[2] / params.max_jerk_m_s3))
        if best is None or excess < best[2]:
            best = (T, peaks, excess)
        if excess <= BOUND_SHARE or T >= longest - 1e-9:
            break
        T = min(longest, T * float(np.clip(excess / BOUND_SHARE, 1.05, 2.0)))
    assert best is not None  # the loop ran at least once
    T, peaks, excess = best
    return T, peaks, bool(excess <= 1.0)
