"""PNG figures of the movement primitives: the paper's Fig. 6 (transitional MP
vs target-crossing DMP) and Fig. 7 (transitions into a periodic MP entered
at different phases).

Both figures work on a learned skill in its surface frame (in-plane x, y
[m]); Fig. 6 also learns the second-order baseline from the same
demonstrated transitional segment, so it needs the demonstration and its
segmentation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lampskit.core.periodic import periodic_state
from lampskit.core.periodic_runner import rollout as periodic_rollout
from lampskit.core.planner import transition_duration
from lampskit.core.planner_types import PlannerParams
from lampskit.core.skill import PeriodicEntry, Skill, TransitionalEntry
from lampskit.core.transitional import TrajectorySamples
from lampskit.core.transitional_plan import rollout as transitional_rollout
from lampskit.core.transitional_plan import similarity_transform
from lampskit.errors import PlanningError
from lampskit.figures.canvas import plt, save_figure
from lampskit.learn.baselines import learn_target_crossing_dmp, rollout_target_crossing_dmp, ruckig_transition
from lampskit.learn.demo import Demonstration
from lampskit.learn.segmentation import Segmentation

DT_S = 0.001
#: Periodic motion shown before and after each transition [s].
CONTEXT_S = 0.6


@dataclass(frozen=True)
class ShownTransition:
    """The transition a figure shows: its MP, the periodic MPs around it (None: that end is the demonstration's own
    state, off any stroke), the start and goal states ((y, v, a), each (2,)), its duration [s] and a caption note."""

    before: PeriodicEntry | None
    tr: TransitionalEntry
    after: PeriodicEntry | None
    start: tuple
    goal: tuple
    T: float
    note: str


def shown_transition(skill: Skill) -> ShownTransition:
    """The first learned transition that joins two periodic MPs (timed as the planner would), else the first one
    into a periodic MP (an approach) or out of one (a retract) as it was demonstrated: from the demonstration's
    own start state, or to its own goal, over its demonstrated duration. Never a demonstrated move mapped onto
    another one (the approach of a single-wipe demo squeezed between two phases of one stroke, 8x faster)."""
    by_segment = {e.segment: e for e in skill.periodic}
    if not skill.transitional:
        raise PlanningError("the skill has no transitional MP to plot")
    for tr in skill.transitional:
        before, after = by_segment.get(tr.segment - 1), by_segment.get(tr.segment + 1)
        if before is not None and after is not None:
            start, goal = _leaving_state(before), _entering_state(after)
            return ShownTransition(before, tr, after, start, goal, _duration(skill, tr, start[0], goal[0]),
                          f"demonstrated segment {tr.segment}")
    ranked = sorted(skill.transitional, key=lambda e: (e.segment + 1 not in by_segment, e.segment))
    tr = ranked[0]
    before, after = by_segment.get(tr.segment - 1), by_segment.get(tr.segment + 1)
    mp = tr.mp
    start = _leaving_state(before) if before is not None else tuple(mp.demo_start)
    goal = _entering_state(after) if after is not None else tuple(mp.demo_goal)
    kind = "approach" if after is not None else "retract" if before is not None else "move"
    return ShownTransition(before, tr, after, start, goal, float(mp.demo_duration_s),
                  f"demonstrated {kind}, segment {tr.segment}, at its own {mp.demo_duration_s:.2f} s "
                  "(no transition between two stains was demonstrated)")


def _leaving_state(entry: PeriodicEntry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State (y, v, a), each (2,), where the demonstrated periodic MP stopped."""
    return periodic_state(entry.mp, entry.mp.phase_end_rad)


def _entering_state(entry: PeriodicEntry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return periodic_state(entry.mp, entry.mp.phase_start_rad)


def _duration(skill: Skill, tr: TransitionalEntry, start: np.ndarray, goal: np.ndarray) -> float:
    """The duration the planner would give this transition [s]."""
    return transition_duration(skill, skill.transitional.index(tr), goal - start, PlannerParams())


def _with_context(before: PeriodicEntry | None, after: PeriodicEntry | None, entry_phase: float,
                  tr: TrajectorySamples):
    """Periodic MP before, the transition, periodic MP after, on one time axis [s] (t = 0 at the start); a side
    without a periodic MP holds the transition's end state still."""
    k = int(round(CONTEXT_S / DT_S))
    t_b = -np.arange(k, 0, -1) * DT_S
    T = tr.t_s[-1]
    t_a = T + np.arange(1, k + 1) * DT_S
    if before is not None:
        mp_b = before.mp
        pre: tuple[np.ndarray, ...] = periodic_state(mp_b, mp_b.phase_end_rad + mp_b.omega_rad_s * t_b)
    else:
        pre = tuple(np.repeat(x[:1], k, axis=0) * (1 if i == 0 else 0) for i, x in
                    enumerate((tr.position_m, tr.velocity_m_s, tr.acceleration_m_s2)))
    if after is not None:
        mp_a = after.mp
        post: tuple[np.ndarray, ...] = periodic_state(mp_a, entry_phase + mp_a.omega_rad_s * (t_a - T))
    else:
        post = tuple(np.repeat(x[-1:], k, axis=0) * (1 if i == 0 else 0) for i, x in
                     enumerate((tr.position_m, tr.velocity_m_s, tr.acceleration_m_s2)))
    t = np.concatenate([t_b, tr.t_s, t_a])
    rows = [np.concatenate([p, x, q]) for p, x, q in zip(pre, (tr.position_m, tr.velocity_m_s, tr.acceleration_m_s2),
                                                         post)]
    return t, rows


def figure_transition_comparison(demo: Demonstration, skill: Skill, seg: Segmentation, path: Path) -> Path:
    """Fig. 6: third-order transitional MP vs target-crossing DMP (and ruckig) between two periodic MPs.

    Rows: position, velocity, acceleration; columns: surface x, y. The
    second-order baseline starts from (y0, v0) only, so its acceleration
    jumps at t = 0 and again at t = T; the transitional MP does not.
    """
    shown = shown_transition(skill)
    before, tr_entry, after, note = shown.before, shown.tr, shown.after, shown.note
    start, goal, T = shown.start, shown.goal, shown.T
    s = seg.segments[tr_entry.segment]
    y_demo = skill.surface.surface_from_world(demo.position_m[s.start : s.end])[:, :2]
    tc_mp = learn_target_crossing_dmp(demo.t_s[s.start : s.end], y_demo)
    M = similarity_transform(tr_entry.mp.demo_displacement_m, goal[0] - start[0])
    curves = {
        "transitional MP (3rd order, ours)": transitional_rollout(tr_entry.mp, start, goal, T, dt_s=DT_S,
                                                                   forcing_transform=M),
        "target-crossing DMP (2nd order)": rollout_target_crossing_dmp(tc_mp, start, goal, T, dt_s=DT_S,
                                                                       forcing_transform=M),
    }
    try:
        curves["ruckig (jerk-limited)"] = ruckig_transition(start, goal, T, dt_s=DT_S)
    except PlanningError:
        pass  # the figure is still meaningful without the third curve
    styles = ["-", "-.", ":"]
    fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex=True)
    units = ["position [m]", "velocity [m/s]", "acceleration [m/s²]"]
    for (name, tr), style in zip(curves.items(), styles):
        t, rows = _with_context(before, after, after.mp.phase_start_rad if after is not None else 0.0, tr)
        for r in range(3):
            for d in range(2):
                ax = axes[r, d]
                periodic = (t < 0) | (t > tr.t_s[-1])
                if style == "-":
                    ax.plot(t[t < 0], rows[r][t < 0, d], color="tab:green", lw=1.5)
                    ax.plot(t[t > tr.t_s[-1]], rows[r][t > tr.t_s[-1], d], color="goldenrod", lw=1.5)
                ax.plot(t[~periodic], rows[r][~periodic, d], style, lw=1.3, label=name)
    for r in range(3):
        axes[r, 0].set_ylabel(units[r])
    for d, name in enumerate("xy"):
        axes[0, d].set_title(f"surface {name}")
        axes[2, d].set_xlabel("time from the start of the transition [s]")
        for r in range(3):
            axes[r, d].axvline(0.0, color="k", lw=0.5)
            axes[r, d].axvline(T, color="k", lw=0.5)
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(f"Transition between two periodic MPs (green: previous, gold: next; {note})" if before and after
                 else f"Transitional MP as demonstrated (green / gold: the periodic MP it leaves / enters; {note})")
    return save_figure(fig, path)


def figure_transition_phases(skill: Skill, path: Path, n_phases: int = 4) -> Path:
    """Fig. 7: the same transition into the next periodic MP entered at ``n_phases`` phases.

    Top: paths in the surface plane; bottom: acceleration magnitude over time.
    """
    shown = shown_transition(skill)
    before, tr_entry, after, note = shown.before, shown.tr, shown.after, shown.note
    if after is None:
        raise PlanningError("no learned transition enters a periodic MP: Fig. 7 has nothing to enter")
    start = shown.start
    mp = after.mp
    phases = mp.phase_start_rad + np.arange(n_phases) * 2 * np.pi / n_phases
    cycle = periodic_rollout(mp, 2 * np.pi / mp.omega_rad_s, DT_S).position_m
    fig, axes = plt.subplots(2, n_phases, figsize=(4 * n_phases, 7))
    for k, phi in enumerate(phases):
        goal = periodic_state(mp, phi)
        T = _duration(skill, tr_entry, start[0], goal[0]) if before is not None else shown.T
        M = similarity_transform(tr_entry.mp.demo_displacement_m, goal[0] - start[0])
        tr = transitional_rollout(tr_entry.mp, start, goal, T, dt_s=DT_S, forcing_transform=M)
        t, rows = _with_context(before, after, phi, tr)
        inside = (t >= 0) & (t <= tr.t_s[-1])
        ax = axes[0, k]
        ax.plot(cycle[:, 0], cycle[:, 1], "--", color="tab:orange", lw=1, label="next periodic MP")
        ax.plot(rows[0][inside, 0], rows[0][inside, 1], color="tab:blue", lw=1.5, label="transitional MP")
        ax.plot(*goal[0], "ko", ms=4)
        ax.set_aspect("equal")
        ax.set_title(f"entry phase {np.degrees(phi % (2 * np.pi)):.0f}°")
        ax.set_xlabel("surface x [m]")
        acc = np.linalg.norm(rows[2], axis=1)
        axes[1, k].plot(t[inside], acc[inside], color="tab:blue", lw=1.3)
        axes[1, k].plot(t[t > tr.t_s[-1]], acc[t > tr.t_s[-1]], "--", color="tab:orange", lw=1.3)
        axes[1, k].plot(t[t < 0], acc[t < 0], color="tab:green", lw=1.3)
        axes[1, k].set_xlabel("time [s]")
    axes[0, 0].set_ylabel("surface y [m]")
    axes[1, 0].set_ylabel("|acceleration| [m/s²]")
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(f"Transitional MP into the next periodic MP at different entry phases ({note})")
    return save_figure(fig, path)
