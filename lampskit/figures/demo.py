"""PNG figures reproducing the paper's Figs. 4-7, plus the generalisation to a new board.

Only matplotlib's Agg backend is used (no display needed). Every writer
returns the path it wrote; files are written atomically.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np

from lampskit.core.skill import Skill
from lampskit.figures.canvas import plt, save_figure
from lampskit.figures.primitives import figure_transition_comparison, figure_transition_phases
from lampskit.learn.demo import Demonstration
from lampskit.learn.segmentation import Segmentation, segment

TRANSITIONAL_COLOUR = "0.6"
log = logging.getLogger(__name__)


def _cluster_colours(labels: np.ndarray) -> list:
    cmap = plt.get_cmap("tab10")
    return [TRANSITIONAL_COLOUR if c < 0 else cmap(c % 10) for c in labels]


def reachability_bars(seg: Segmentation) -> tuple[np.ndarray, np.ndarray]:
    """Fig. 4's bars: the reachability [m] (M,) in OPTICS order (the first, infinite, drawn at the highest) and the
    final label of the *point at each position of the ordering* (M,) (its sample's segment; -1 transitional)."""
    reach = seg.reachability_plot
    finite = np.isfinite(reach)
    top = np.nanmax(reach[finite]) if finite.any() else 1.0
    return np.where(finite, reach, top), seg.ordering_labels


def figure_reachability(seg: Segmentation, path: Path) -> Path:
    """Fig. 4: reachability distance in OPTICS order, valleys = periodic MPs, with the threshold; each bar coloured
    by the final label of the point at that position of the ordering."""
    heights, labels = reachability_bars(seg)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.bar(np.arange(len(heights)), heights, width=1.0, color=_cluster_colours(labels), linewidth=0)
    if seg.threshold is not None:
        ax.axhline(seg.threshold, color="k", ls="--", lw=1, label=f"threshold {seg.threshold * 1000:.1f} mm")
        ax.legend(loc="upper right")
    ax.set_xlabel("OPTICS ordering")
    ax.set_ylabel("reachability distance [m]")
    ax.set_title("Ordering-reachability plot (valleys: periodic MPs, peaks: transitional MPs)")
    return save_figure(fig, path)


def figure_segmentation_comparison(
    demo: Demonstration, seg: Segmentation, path: Path, others: dict[str, Segmentation] | None = None
) -> Path:
    """Fig. 5: segmentation by OPTICS vs K-Means vs Affinity Propagation, in the demonstration's plane."""
    if others is None:
        others = {m: segment(demo, method=m) for m in ("kmeans", "affinity")}
    methods = {"OPTICS (ours)": seg, "K-Means": others["kmeans"], "Affinity Propagation": others["affinity"]}
    centred = demo.position_m - demo.position_m.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    xy = centred @ vt[:2].T
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5), sharex=True, sharey=True)
    for ax, (name, s) in zip(axes, methods.items()):
        ax.scatter(xy[:, 0], xy[:, 1], c=_cluster_colours(s.labels), s=3)
        n_per = sum(x.kind == "periodic" for x in s.segments)
        ax.set_title(f"{name}: {n_per} periodic segment(s)")
        ax.set_aspect("equal")
        ax.set_xlabel("principal axis 1 [m]")
    axes[0].set_ylabel("principal axis 2 [m]")
    fig.suptitle("Segmentation of the demonstration (grey: transitional)")
    return save_figure(fig, path)


def figure_generalisation(skill: Skill, plan_, ro, path: Path) -> Path:
    """The plan rolled out on a new board: path coloured by MP kind, stains drawn to size."""
    fig, ax = plt.subplots(figsize=(8, 5.5))
    per = ro.kind == "periodic"
    ax.scatter(ro.position_m[~per, 0], ro.position_m[~per, 1], s=1, c="tab:purple", label="transitional MP")
    ax.scatter(ro.position_m[per, 0], ro.position_m[per, 1], s=1, c="goldenrod", label="periodic MP")
    for k, w in enumerate(plan_.wipes):
        ax.add_patch(plt.Circle(w.stain.centre_m, w.stain.size_m / 2, color="k", alpha=0.15))
        ax.annotate(f"{k + 1}", w.stain.centre_m, ha="center", va="center")
    ax.plot(*ro.position_m[0], "ko", ms=4, label="start")
    ax.set_aspect("equal")
    ax.set_xlabel("board x [m]")
    ax.set_ylabel("board y [m]")
    ax.legend(loc="best", markerscale=6)
    ax.set_title("Skill generalised to a new board (stains in visiting order)")
    return save_figure(fig, path)


def write_generalisation_figure(skill: Skill, plan_, ro, path: Path) -> Path:
    return figure_generalisation(skill, plan_, ro, path)


def write_figures(
    demo: Demonstration,
    skill: Skill,
    seg: Segmentation,
    folder: Path,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[Path]:
    """Write Figs. 4-7 into ``folder``; returns the paths.

    Figs. 6 and 7 need a learned transitional MP; without one they are
    skipped (logged), the others are still written.
    """
    folder = Path(folder)
    jobs = [
        lambda: figure_reachability(seg, folder / "fig4_reachability.png"),
        lambda: figure_segmentation_comparison(demo, seg, folder / "fig5_segmentation_methods.png"),
    ]
    if skill.transitional:
        jobs += [
            lambda: figure_transition_comparison(demo, skill, seg, folder / "fig6_transition_vs_target_crossing.png"),
            lambda: figure_transition_phases(skill, folder / "fig7_transition_entry_phases.png"),
        ]
    else:
        log.warning("the skill has no transitional MP: Figs. 6 and 7 are not drawn")
    paths = []
    for k, job in enumerate(jobs):
        if progress is not None:
            progress("figures", k, len(jobs))
        paths.append(job())
    if progress is not None:
        progress("figures", len(jobs), len(jobs))
    return paths
