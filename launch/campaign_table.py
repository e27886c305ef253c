"""A campaign's table and plots (:mod:`launch.campaign`): one row per cell from its report and bounds, when a cell
succeeds, the summary per board and wiping mode, the markdown table and ``campaign.png``."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from .campaign_bounds import cell_bound_s
from .campaign_cells import Cell

#: A cell succeeds when it removed at least this share of its dirt (and nothing faulted).
CLEAN_SHARE = 0.98
#: The random-board benchmark's bounds a cell is counted against: the peak contact force [N] over every physics step,
#: the largest share of a joint's speed limit.
FORCE_BOUND_N = 20.0
JOINT_SPEED_BOUND = 0.8
#: Report fault phases that count as a fault of the cell (ROBOT events, e.g. a brake on a stale command, do not).
FAULT_PHASES = ("FAULT", "ESTOP", "CELL", "SERVICE")


def row_of(cell: Cell, report: dict[str, Any] | None, bound_s: float, run_dir: str, why: str = "",
           stains: tuple[list[float], np.ndarray] | None = None, felt: dict[str, float] | None = None,
           speed_m_s: float = 0.5) -> dict[str, Any]:
    """One table row: the cell, what its report says (None: it left no report, ``why``), its lower bound and,
    given its ``stains`` (areas, centres) and the ``felt`` model, its cell bound at ``speed_m_s``."""
    row: dict[str, Any] = {**asdict(cell), "name": cell.name, "run_dir": run_dir, "lower_bound_s": bound_s}
    if report is None:
        return {**row, "outcome": "no report", "success": False, "why": why}
    phases = report.get("phase_time_s") or {}
    start = report.get("skill_start_s")
    # the retreat into the final DONE (a re-pass's retreat and look before it are not fixed moves); reports
    # from before that field: the RETREAT phase's whole time
    retreat = report.get("final_retreat_s")
    retreat = float(phases.get("RETREAT", 0.0)) if retreat is None else float(retreat)
    fixed = float(start) + retreat if start is not None and phases else float("nan")
    cell_b = cell_bound_s(fixed, *stains, felt, speed_m_s) if stains is not None and felt and fixed == fixed \
        else float("nan")
    faults = [f for f in report.get("faults", []) if f.get("phase") in FAULT_PHASES]
    removed = float(report.get("dirt_removed_fraction", 0.0))
    cell_s = float(report.get("sim_time_s", float("nan")))
    end = report.get("job_end_s")
    robot_s = float(end) if end is not None else cell_s  # to DONE; a run that did not end DONE: the whole cell
    peaks = (report.get("motion_peaks") or {}).get("all", {})
    controller_counters = (report.get("counters") or {}).get("controller", {})
    return {**row, "outcome": report.get("outcome", "?"), "dirt_removed": removed, "robot_time_s": robot_s,
            "cell_time_s": cell_s,
            "cell_time_over_cell_bound": cell_s / cell_b if cell_b > 0 else float("nan"),
            "time_over_bound": robot_s / bound_s if bound_s > 0 else float("nan"),
            "phase_time_s": phases, "fixed_moves_s": fixed, "cell_bound_s": cell_b,
            "time_over_cell_bound": robot_s / cell_b if cell_b > 0 else float("nan"),
            "wipe_s": float(phases.get("WIPE", float("nan"))),
            "transition_s": float(phases.get("TRANSITION", float("nan"))),
            "time_per_stain_s": (robot_s - fixed) / cell.stains,
            "peak_accel_m_s2": float(peaks.get("accel_m_s2", float("nan"))),
            # over every physics step where the report has it (impacts of a few ms), else the 10 Hz truth's
            "peak_contact_force_n": float(report.get("peak_contact_force_n", report.get("max_contact_force_n",
                                                                                         float("nan")))),
            "peak_jerk_m_s3": float(peaks.get("jerk_m_s3", float("nan"))),
            "peak_speed_m_s": float(peaks.get("speed_m_s", float("nan"))),
            "faults": len(faults), "fault_reasons": [f.get("reason", "") for f in faults],
            "robot_events": sum(1 for f in report.get("faults", []) if f.get("phase") == "ROBOT"),
            "tracking_rms_m": float(report.get("tracking_rms_m", float("nan"))),
            "force_std_n": float(report.get("normal_force_std_n", float("nan"))),
            "max_joint_speed_ratio": float(report.get("max_joint_speed_ratio", float("nan"))),
            "stains_out_of_reach": int(controller_counters.get("stains_out_of_reach", 0)),
            "final_reason": report.get("final_reason", ""),
            "success": removed >= CLEAN_SHARE and not faults, "why": why}


def board_group(board: str) -> str:
    """The table's group of a cell's board: a preset's name, a TOML file's stem, ``random`` for every
    ``random:N``."""
    return "random" if board.startswith("random:") else Path(board).stem


def group_of(row: dict[str, Any]) -> str:
    """A row's group in the table: board and wiping mode, and its plant when not the nominal arm."""
    plant = row.get("plant", "nominal")
    return f"{board_group(row['board'])} {row.get('wiping', 'fixed')}" + ("" if plant == "nominal" else f" {plant}")


def summarize(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per board (its name), wiping mode and plant, and ``all``: runs, success rate, dirt removed (median, min),
    robot time and its ratio to the lower bound (median), peak force and jerk (max), tracking and force spread
    (median, max), joint speed (max), faults (sum); cells where the robot side acted (braked, yielded, held), over
    :data:`FORCE_BOUND_N` or :data:`JOINT_SPEED_BOUND`, whose controller skipped a stain out of the arm's reach,
    without a report."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        wiping = r.get("wiping", "fixed")
        groups.setdefault(group_of(r), []).append(r)
        groups.setdefault(f"all {wiping}", []).append(r)
    out = {}
    for name, rs in groups.items():
        ran = [r for r in rs if r["outcome"] != "no report"]

        def med(key: str) -> float:
            return float(np.median([r.get(key, float("nan")) for r in ran])) if ran else float("nan")  # noqa: B023 (called within this iteration)

        def top(key: str) -> float:
            values = np.array([r.get(key, np.nan) for r in ran], float)  # noqa: B023 (called within this iteration)
            return float(np.nanmax(values)) if np.any(np.isfinite(values)) else float("nan")

        out[name] = {"runs": len(rs), "success_rate": sum(r["success"] for r in rs) / len(rs),
                     "dirt_removed_median": med("dirt_removed"),
                     "dirt_removed_min": float(min(r["dirt_removed"] for r in ran)) if ran else float("nan"),
                     "robot_time_median_s": med("robot_time_s"), "time_over_bound_median": med("time_over_bound"),
                     "time_over_cell_bound_median": med("time_over_cell_bound"),
                     "time_over_cell_bound_max": top("time_over_cell_bound"),
                     "cell_time_over_cell_bound_median": med("cell_time_over_cell_bound"),
                     "time_per_stain_median_s": med("time_per_stain_s"),
                     "peak_speed_max_m_s": top("peak_speed_m_s"), "peak_accel_max_m_s2": top("peak_accel_m_s2"),
                     "time_over_bound_max": top("time_over_bound"),
                     "peak_contact_force_max_n": top("peak_contact_force_n"),
                     "peak_jerk_max_m_s3": top("peak_jerk_m_s3"), "faults": sum(r["faults"] for r in ran),
                     "tracking_rms_median_m": med("tracking_rms_m"), "tracking_rms_max_m": top("tracking_rms_m"),
                     "force_std_median_n": med("force_std_n"), "force_std_max_n": top("force_std_n"),
                     "joint_speed_ratio_max": top("max_joint_speed_ratio"),
                     "robot_acted_cells": sum(1 for r in ran if r.get("robot_events", 0)),
                     "force_over_bound_cells": sum(1 for r in ran
                                                   if r.get("peak_contact_force_n", 0.0) > FORCE_BOUND_N),
                     "joint_over_bound_cells": sum(1 for r in ran
                                                   if r.get("max_joint_speed_ratio", 0.0) > JOINT_SPEED_BOUND),
                     "out_of_reach_cells": sum(1 for r in ran if r.get("stains_out_of_reach", 0)),
                     "no_report": len(rs) - len(ran)}
    return out


def markdown(summary: dict[str, dict[str, Any]], rows: list[dict[str, Any]], command: str) -> str:
    """The campaign's table (per board and wiping mode, then over all) and one line per cell."""
    head = ("| board, wiping | runs | success (>= 98 % removed, no fault) | dirt removed median / min "
            "| robot time median [s] | time per stain median [s] | time / cell bound median (max); cell time "
            "| time / lower bound median | peak speed / accel. / jerk max [m/s, m/s^2, m/s^3] "
            "| peak contact force max [N] (cells > 20 N) | force std median (max) [N] | tracking RMS median (max) [mm] "
            "| joint speed max [share of limit] (cells > 0.8) | faults | cells the robot side acted "
            "| cells with stains out of reach | no report |\n"
            "|---|---:|---:|---|---:|---:|---|---:|---|---:|---|---|---:|---:|---:|---:|---:|")
    lines = [head]
    for name in sorted(summary, key=lambda n: (n.startswith("all "), n.split()[-1], n)):
        s = summary[name]
        lines.append(f"| {name} | {s['runs']} | {s['success_rate']:.0%} | {s['dirt_removed_median']:.1%} / "
                     f"{s['dirt_removed_min']:.1%} | {s['robot_time_median_s']:.1f} | "
                     f"{s.get('time_per_stain_median_s', float('nan')):.1f} | "
                     f"{s.get('time_over_cell_bound_median', float('nan')):.2f} "
                     f"({s.get('time_over_cell_bound_max', float('nan')):.2f}); "
                     f"{s.get('cell_time_over_cell_bound_median', float('nan')):.2f} | "
                     f"{s['time_over_bound_median']:.1f} | "
                     f"{s.get('peak_speed_max_m_s', float('nan')):.2f} / "
                     f"{s.get('peak_accel_max_m_s2', float('nan')):.2f} / "
                     f"{s['peak_jerk_max_m_s3']:.0f} | {s['peak_contact_force_max_n']:.1f} "
                     f"({s.get('force_over_bound_cells', 0)}) | "
                     f"{s.get('force_std_median_n', float('nan')):.2f} ({s.get('force_std_max_n', float('nan')):.2f})"
                     f" | {1e3 * s.get('tracking_rms_median_m', float('nan')):.2f} "
                     f"({1e3 * s.get('tracking_rms_max_m', float('nan')):.2f}) | "
                     f"{s.get('joint_speed_ratio_max', float('nan')):.2f} ({s.get('joint_over_bound_cells', 0)}) | "
                     f"{s['faults']} | "
                     f"{s.get('robot_acted_cells', 0)} | {s.get('out_of_reach_cells', 0)} | {s['no_report']} |")
    lines += ["", "| cell | outcome | removed | robot time [s] | cell bound [s] | lower bound [s] | peak force [N] "
              "| peak jerk [m/s^3] | faults, else why DONE left stains |",
              "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if r["outcome"] == "no report":
            lines.append(f"| {r['name']} | no report: {r['why']} | - | - | - | {r['lower_bound_s']:.1f} | - | - | - |")
            continue
        lines.append(f"| {r['name']} | {r['outcome']} | {r['dirt_removed']:.1%} | {r['robot_time_s']:.1f} | "
                     f"{r.get('cell_bound_s', float('nan')):.1f} | {r['lower_bound_s']:.1f} | "
                     f"{r['peak_contact_force_n']:.1f} | {r['peak_jerk_m_s3']:.0f} | "
                     f"{'; '.join(r['fault_reasons']) or r.get('final_reason') or '-'} |")
    return "\n".join(lines) + f"\n\nreproduce: {command}\n"


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Robot time against its cell bound per board and wiping mode (with 1x and 2x lines), and dirt removed per
    cell."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lampskit.atomic import write_atomic

    ran = [r for r in rows if r["outcome"] != "no report"]
    bound = [r.get("cell_bound_s", float("nan")) for r in ran]
    key = "cell_bound_s" if ran and np.isfinite(bound).all() else "lower_bound_s"
    plants = any(r.get("plant", "nominal") != "nominal" for r in ran)
    fig, axes = plt.subplots(1, 3 if plants else 2, figsize=(16 if plants else 11, 4.2))
    ax1, ax2 = axes[0], axes[1]
    for group in sorted({group_of(r) for r in ran}):
        rs = [r for r in ran if group_of(r) == group]
        ax1.scatter([r[key] for r in rs], [r["robot_time_s"] for r in rs], label=group, s=16,
                    marker="o" if "fixed" in group.split() else "^")
    top = max([r[key] for r in ran] + [1.0])
    for f, style in ((1.0, "k-"), (2.0, "k--")):
        ax1.plot([0, top], [0, f * top], style, lw=0.8, label=f"{f:g}x the bound")
    what = "cell bound" if key == "cell_bound_s" else "lower bound"
    ax1.set(xlabel=f"{what} [s]", ylabel="robot time [s]", title=f"robot time against its {what}")
    ax1.legend(fontsize=7)
    ax2.bar(range(len(ran)), [100 * r["dirt_removed"] for r in ran],
            color=["tab:green" if r["success"] else "tab:red" for r in ran])
    ax2.axhline(100 * CLEAN_SHARE, color="k", lw=0.8)
    ax2.set(xlabel="cell", ylabel="dirt removed [%]", title="dirt removed (red: not a success)",
            ylim=(min([90.0] + [100 * r["dirt_removed"] for r in ran]), 100.5))
    if plants:
        from .campaign_plants import plant_error

        ax3 = axes[2]
        for plant in sorted({r.get("plant", "nominal") for r in ran}):
            rs = [r for r in ran if r.get("plant", "nominal") == plant]
            ax3.scatter([100 * plant_error(plant, int(r["seed"])) for r in rs],
                        [1e3 * r.get("tracking_rms_m", float("nan")) for r in rs], label=plant, s=16)
        ax3.set(xlabel="mass the model has wrong [% of the arm's]", ylabel="tracking RMS while wiping [mm]",
                title="tracking against the plant's model error")
        ax3.legend(fontsize=7)
    fig.tight_layout()
    write_atomic(path, lambda f: fig.savefig(f, format="png", dpi=100))
    plt.close(fig)
