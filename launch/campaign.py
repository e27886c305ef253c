"""A campaign of seeded cells: many boards run whole, several at once, summed up in a table and plots.

``lamps campaign --seeds 0-49 --stains 1-6 --boards wall,table,config/boards/tilted.toml --wiping fixed,adaptive``

Cell k runs seed ``s`` (the k-th of ``--seeds``) with ``lo + s mod (hi - lo + 1)``
stains of ``--stains lo-hi`` on board ``boards[s mod len(boards)]``, so every board
and every stain count is covered in turn and a cell is the same whatever else
the campaign holds; each seed runs once per ``--wiping`` mode (``fixed``: the
periodic MP set once per stain; ``adaptive``: shaped to the stain and
following its ink, ``[controller.planner] adaptive``). Each cell is ``lamps up`` in lock-step (deterministic for
its seed) with the skill learned once, in its own run folder under
``OUT/cells/``; up to ``--jobs`` run at once, each on its own ports.

From each cell's ``report.json``: outcome, dirt removed, robot time (to the
DONE the run ended in, ``job_end_s``; the cell time, ``sim_time_s``, also
counts the launcher's 2.5 s look that DONE holds, and is kept beside it), peak
contact force, peak jerk of the executed reference, faults, and a **lower
bound** on the robot time (:func:`lower_bound_s`): the stains' dirt area swept
by the pad's long side at the controller's Cartesian speed limit, plus the
shortest network joining the stains (a minimum spanning tree, no longer than
any path through them) at that speed. That bound leaves out everything a run
does besides sweeping and travelling, so a second one, the **cell bound**
(:func:`cell_bound_s`), adds the run's fixed moves as it executed them (the
robot time before the skill's first transition: waiting for the peers, the
survey's flight and look, the approach, touch-down and force ramp; and the
RETREAT phase: ramp-out, lift-off, flight back; the same whatever the
wiping) and counts
the sliding the felt needs (:func:`felt_path_m`) at the planner's speed
bound. A cell *succeeds* when it removed at least :data:`CLEAN_SHARE` of its
dirt and nothing faulted.

Writes ``campaign.json`` (every cell, the summary), ``campaign.md`` (the table
per board and wiping mode, and over all) and ``campaign.png`` (robot time
against the lower bound, dirt removed per cell), each atomically. Exit 0 when
every cell left a report (whatever it shows), 1 with the reason otherwise.
``--summarize DIR [DIR ...]`` runs nothing: it reads the cells of earlier
campaigns (their ``campaign.json`` and each cell's ``report.json`` as it is
now) and writes one table of them all into ``--out``.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import logging
import math
import os
import random
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lampskit.atomic import write_text_atomic
from lampskit.errors import LampsError

#: A cell succeeds when it removed at least this share of its dirt (and nothing faulted).
CLEAN_SHARE = 0.98
#: Report fault phases that count as a fault of the cell (ROBOT events, e.g. a brake on a stale command, do not).
FAULT_PHASES = ("FAULT", "ESTOP", "CELL", "SERVICE")
#: Cell k listens on ports from base + (k mod PORT_SLOTS) * PORT_STRIDE (a cell uses fewer than 10), base one of
#: PORT_BASES picked per campaign (ports a campaign just closed stay unbindable for a minute); a busy port moves
#: the cell PORT_SLOTS * PORT_STRIDE up. All below the kernel's ephemeral range (32768).
PORT_BASES, PORT_SLOTS, PORT_STRIDE = (20000, 23000, 26000), 100, 10
BOARD_NAMES = ("wall", "table", "vertical", "horizontal")
WIPINGS = ("fixed", "adaptive")
log = logging.getLogger(__name__)


class CampaignError(LampsError):
    """A clear, one-line reason why the campaign could not run."""


@dataclass(frozen=True)
class Cell:
    """One seeded board: ``seed``, ``stains`` (count), ``board`` (preset name or TOML file), ``wiping`` mode."""

    seed: int
    stains: int
    board: str
    wiping: str = "fixed"

    @property
    def name(self) -> str:
        suffix = "-adaptive" if self.wiping == "adaptive" else ""
        return f"{Path(self.board).stem}-s{self.seed}-n{self.stains}{suffix}"


# ---------------------------------------------------------------------------------------------- pure parts
def parse_range(text: str, what: str) -> list[int]:
    """``"0-49"``, ``"3"`` or ``"1,4,7-9"`` as a sorted list of distinct non-negative integers."""
    out: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        try:
            lo, _, hi = part.partition("-")
            a, b = int(lo), int(hi) if hi else int(lo)
        except ValueError:
            raise CampaignError(f"--{what} {text!r}: {part!r} is not N or N-M (non-negative integers)") from None
        if a < 0 or b < a:
            raise CampaignError(f"--{what} {text!r}: {part!r} must satisfy 0 <= N <= M")
        out.update(range(a, b + 1))
    return sorted(out)


def cells_of(seeds: list[int], stains: list[int], boards: list[str], wipings: tuple[str, ...] = ("fixed",)
             ) -> list[Cell]:
    """The campaign's cells: seed s gets ``stains[s mod len]`` stains on ``boards[s mod len]``, once per wiping
    mode."""
    if not seeds or not stains or not boards or not wipings:
        raise CampaignError("a campaign needs at least one seed, one stain count, one board and one wiping mode")
    bad = [w for w in wipings if w not in WIPINGS]
    if bad:
        raise CampaignError(f"--wiping: {bad[0]!r} is not one of {WIPINGS}")
    return [Cell(s, stains[s % len(stains)], boards[s % len(boards)], w) for s in seeds for w in wipings]


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
    """The cell bound [s]: the run's fixed moves (before the skill's start + the final RETREAT, as executed) + each stain's
    :func:`felt_path_m` + the stains' minimum spanning tree, both at ``speed_m_s``. ``felt``: ``pad_area_m2``,
    ``rate_per_n_m``, ``force_over_threshold_n``, ``level``."""
    wipe = sum(felt_path_m(a, **felt) for a in areas_m2)
    return fixed_moves_s + (wipe + mst_length_m(np.asarray(centres_m, float))) / speed_m_s


def felt_model() -> dict[str, float]:
    """The sim's removal law at the controller's wiping force, and the report's level of a wiped stain."""
    from controller.params import ControllerParams
    from interfaces.description import PAD_SIZE_M
    from sim.params import SimParams

    from .report import TRUTH_LEVEL

    dirt, force = SimParams.from_table({}).dirt, ControllerParams.from_table({}).force
    return {"pad_area_m2": PAD_SIZE_M[0] * PAD_SIZE_M[1], "rate_per_n_m": dirt.rate_per_n_m,
            "force_over_threshold_n": force.target_n - dirt.threshold_force_n, "level": TRUTH_LEVEL}


def cell_stains(cell: Cell, board_table: dict[str, Any]) -> tuple[list[float], np.ndarray]:
    """The stains the sim makes for ``cell`` (the sim's own seeded generator): areas [m^2] (ellipses of the
    stain's extent and aspect) and centres (n, 2) [m]."""
    from sim.board import board_from_params
    from sim.core import make_stains
    from sim.params import SimParams

    params = SimParams.from_table({"seed": cell.seed, "dirt": {"stains": cell.stains}, "board": board_table})
    stains = make_stains(params, board_from_params(params.board))
    areas = [math.pi / 4 * s.size_m * s.size_m / s.aspect for s in stains]
    return areas, np.array([s.centre_m for s in stains], float).reshape(-1, 2)


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
            "peak_contact_force_n": float(report.get("max_contact_force_n", float("nan"))),
            "peak_jerk_m_s3": float(peaks.get("jerk_m_s3", float("nan"))),
            "peak_speed_m_s": float(peaks.get("speed_m_s", float("nan"))),
            "faults": len(faults), "fault_reasons": [f.get("reason", "") for f in faults],
            "robot_events": sum(1 for f in report.get("faults", []) if f.get("phase") == "ROBOT"),
            "success": removed >= CLEAN_SHARE and not faults, "why": why}


def summarize(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per board (its name) and ``all``: runs, success rate, dirt removed (median, min), robot time and its ratio
    to the lower bound (median), peak force and jerk (max), faults (sum), cells without a report."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        wiping = r.get("wiping", "fixed")
        groups.setdefault(f"{Path(r['board']).stem} {wiping}", []).append(r)
        groups.setdefault(f"all {wiping}", []).append(r)
    out = {}
    for name, rs in groups.items():
        ran = [r for r in rs if r["outcome"] != "no report"]

        def med(key: str) -> float:
            return float(np.median([r.get(key, float("nan")) for r in ran])) if ran else float("nan")

        def top(key: str) -> float:
            values = np.array([r.get(key, np.nan) for r in ran], float)
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
                     "time_over_bound_max": top("time_over_bound"), "peak_contact_force_max_n": top("peak_contact_force_n"),
                     "peak_jerk_max_m_s3": top("peak_jerk_m_s3"), "faults": sum(r["faults"] for r in ran),
                     "no_report": len(rs) - len(ran)}
    return out


def markdown(summary: dict[str, dict[str, Any]], rows: list[dict[str, Any]], command: str) -> str:
    """The campaign's table (per board and wiping mode, then over all) and one line per cell."""
    head = ("| board, wiping | runs | success (>= 98 % removed, no fault) | dirt removed median / min "
            "| robot time median [s] | time per stain median [s] | time / cell bound median (max); cell time "
            "| time / lower bound median | peak speed / accel. / jerk max [m/s, m/s^2, m/s^3] "
            "| peak contact force max [N] | faults | no report |\n"
            "|---|---:|---:|---|---:|---:|---|---:|---|---:|---:|---:|")
    lines = [head]
    for name in sorted(summary, key=lambda n: (n.startswith("all "), n.split()[-1], n)):
        s = summary[name]
        lines.append(f"| {name} | {s['runs']} | {s['success_rate']:.0%} | {s['dirt_removed_median']:.1%} / "
                     f"{s['dirt_removed_min']:.1%} | {s['robot_time_median_s']:.1f} | "
                     f"{s.get('time_per_stain_median_s', float('nan')):.1f} | "
                     f"{s.get('time_over_cell_bound_median', float('nan')):.2f} "
                     f"({s.get('time_over_cell_bound_max', float('nan')):.2f}); "
                     f"{s.get('cell_time_over_cell_bound_median', float('nan')):.2f} | {s['time_over_bound_median']:.1f} | "
                     f"{s.get('peak_speed_max_m_s', float('nan')):.2f} / "
                     f"{s.get('peak_accel_max_m_s2', float('nan')):.2f} / "
                     f"{s['peak_jerk_max_m_s3']:.0f} | {s['peak_contact_force_max_n']:.1f} | {s['faults']} | "
                     f"{s['no_report']} |")
    lines += ["", "| cell | outcome | removed | robot time [s] | cell bound [s] | lower bound [s] | peak force [N] "
              "| peak jerk [m/s^3] | faults |", "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if r["outcome"] == "no report":
            lines.append(f"| {r['name']} | no report: {r['why']} | - | - | - | {r['lower_bound_s']:.1f} | - | - | - |")
            continue
        lines.append(f"| {r['name']} | {r['outcome']} | {r['dirt_removed']:.1%} | {r['robot_time_s']:.1f} | "
                     f"{r.get('cell_bound_s', float('nan')):.1f} | {r['lower_bound_s']:.1f} | "
                     f"{r['peak_contact_force_n']:.1f} | {r['peak_jerk_m_s3']:.0f} | "
                     f"{'; '.join(r['fault_reasons']) or '-'} |")
    return "\n".join(lines) + f"\n\nreproduce: {command}\n"


# ---------------------------------------------------------------------------------------------- processes
def _board_table(board: str) -> dict[str, Any]:
    """The ``[sim.board]`` table of a preset name or a board TOML file (as ``lamps up --board`` reads it)."""
    from launch.cli import BOARDS, UpError, board_env

    if board in BOARDS:
        return {"preset": BOARDS[board]}
    try:
        env = board_env(board)
    except UpError as exc:
        raise CampaignError(str(exc)) from None
    return {k.removeprefix("LAMPS__SIM__BOARD__").lower(): json.loads(v) for k, v in env.items()}


def _learn_skill(out: Path) -> Path:
    """The bundled demo learned once, as ``lamps up`` learns it by default."""
    learn = out / "learn"
    log.info("learning the bundled demo into %s", learn)
    r = subprocess.run([sys.executable, "-m", "interfaces.cli", "demo", "--stains", "3", "--seed", "0", "--out",
                        str(learn)], capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
    if r.returncode != 0 or not (learn / "skill.json").is_file():
        raise CampaignError(f"learning the skill failed (exit {r.returncode}): {r.stderr.strip()[-300:]}")
    return learn / "skill.json"


def _run_cell(k: int, cell: Cell, skill: Path, out: Path, max_duration_s: float,
              port_base: int) -> tuple[dict | None, str, str]:
    """``lamps up`` for one cell: (its report or None, its run folder, why there is none)."""
    run_dir = out / "cells" / cell.name
    base = port_base + (k % PORT_SLOTS) * PORT_STRIDE
    why = ""
    for attempt in range(3):  # a port taken by something else: again on another range
        argv = [sys.executable, "-m", "interfaces.cli", "up", "--seed", str(cell.seed), "--stains", str(cell.stains),
                "--board", cell.board, "--skill", str(skill), "--out", str(run_dir), "--mode", "lockstep",
                "--port-base", str(base + attempt * PORT_SLOTS * PORT_STRIDE), "--max-duration", str(max_duration_s),
                "-q"]
        log.info("cell %s: %s", cell.name, " ".join(argv[2:]))
        env = {**os.environ, "MPLBACKEND": "Agg",
               "LAMPS__CONTROLLER__PLANNER__ADAPTIVE": "true" if cell.wiping == "adaptive" else "false"}
        r = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=max_duration_s + 120)
        report = run_dir / "report.json"
        if report.is_file():
            return json.loads(report.read_text()), str(run_dir), ""
        why = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
        if "already in use" not in why:
            break
    return None, str(run_dir), why


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
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for group in sorted({f"{Path(r['board']).stem} {r.get('wiping', 'fixed')}" for r in ran}):
        rs = [r for r in ran if f"{Path(r['board']).stem} {r.get('wiping', 'fixed')}" == group]
        ax1.scatter([r[key] for r in rs], [r["robot_time_s"] for r in rs], label=group, s=16,
                    marker="o" if group.endswith("fixed") else "^")
    top = max([r[key] for r in ran] + [1.0])
    for f, style in ((1.0, "k-"), (2.0, "k--")):
        ax1.plot([0, top], [0, f * top], style, lw=0.8, label=f"{f:g}x the bound")
    what = "cell bound" if key == "cell_bound_s" else "lower bound"
    ax1.set(xlabel=f"{what} [s]", ylabel="robot time [s]", title=f"robot time against its {what}")
    ax1.legend(fontsize=7)
    ax2.bar(range(len(ran)), [100 * r["dirt_removed"] for r in ran],
            color=["tab:green" if r["success"] else "tab:red" for r in ran])
    ax2.axhline(100 * CLEAN_SHARE, color="k", lw=0.8)
    ax2.set(xlabel="cell", ylabel="dirt removed [%]", ylim=(min([90.0] + [100 * r["dirt_removed"] for r in ran]), 100.5),
            title="dirt removed (red: not a success)")
    fig.tight_layout()
    write_atomic(path, lambda f: fig.savefig(f, format="png", dpi=100))
    plt.close(fig)


def _bounds(cells: list[Cell]) -> tuple[dict[Cell, tuple], dict[Cell, float], dict[str, float], float, float]:
    """Per cell its stains (areas, centres) and lower bound; the felt model; the planner's speed bound and the
    pad's width."""
    from controller.params import ControllerParams
    from interfaces.description import PAD_SIZE_M
    from lampskit.core.planner_types import PlannerParams

    tables = {b: _board_table(b) for b in dict.fromkeys(c.board for c in cells)}
    speed, pad = ControllerParams.from_table({}).limits.max_speed_m_s, max(PAD_SIZE_M)
    stains = {c: cell_stains(c, tables[c.board]) for c in cells}
    return (stains, {c: lower_bound_s(*stains[c], pad, speed) for c in cells}, felt_model(),
            PlannerParams().max_speed_m_s, pad)


def _write_outputs(out: Path, rows: list[dict[str, Any]], command: str, extra: dict[str, Any]) -> dict[str, Any]:
    summary = summarize(rows)
    result = {"schema": "lamps-campaign/1", "command": command, "clean_share": CLEAN_SHARE, **extra,
              "summary": summary, "cells": rows}
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "campaign.json", json.dumps(result, indent=1) + "\n")
    write_text_atomic(out / "campaign.md", markdown(summary, rows, command))
    plot(rows, out / "campaign.png")
    return result


def run_campaign(cells: list[Cell], out: Path, jobs: int, skill: Path | None, max_duration_s: float,
                 command: str, echo=print) -> dict[str, Any]:
    """Run every cell (``jobs`` at once), write campaign.json, .md and .png into ``out``; returns the json."""
    out.mkdir(parents=True, exist_ok=True)
    stains, bounds, felt, v_plan, pad = _bounds(cells)
    skill = skill or _learn_skill(out)
    rows: list[dict[str, Any] | None] = [None] * len(cells)
    t0 = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
        port_base = random.choice(PORT_BASES)
        futures = {pool.submit(_run_cell, k, c, skill, out, max_duration_s, port_base): k for k, c in enumerate(cells)}
        for fut in concurrent.futures.as_completed(futures):
            k = futures[fut]
            report, run_dir, why = fut.result()
            rows[k] = row_of(cells[k], report, bounds[cells[k]], run_dir, why, stains[cells[k]], felt, v_plan)
            r = rows[k]
            echo(f"[{sum(x is not None for x in rows)}/{len(cells)} {time.monotonic() - t0:.0f} s] {cells[k].name}: "
                 + (f"no report ({why})" if report is None else
                    f"{r['outcome']}, {r['dirt_removed']:.1%} removed in {r['robot_time_s']:.1f} s "
                    f"({r['time_over_cell_bound']:.2f}x the cell bound)"))
    done = [r for r in rows if r is not None]
    return _write_outputs(out, done, command, {"pad_width_m": pad, "felt": felt, "planner_speed_m_s": v_plan})


def summarize_campaigns(dirs: list[Path], out: Path, command: str) -> dict[str, Any]:
    """One table of earlier campaigns' cells (``DIR/campaign.json``), each cell's ``report.json`` as it is now
    (rebuilt by ``lamps report`` after the report gained a field, say) and today's bounds."""
    entries = []
    for d in dirs:
        path = d / "campaign.json"
        try:
            data = json.loads(path.read_text())
            cells = [(Cell(int(c["seed"]), int(c["stains"]), str(c["board"]), str(c.get("wiping", "fixed"))),
                      str(c["run_dir"])) for c in data["cells"]]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise CampaignError(f"--summarize {d}: cannot read {path.name}: {exc}") from None
        entries += cells
    names = [c.name for c, _ in entries]
    if len(set(names)) != len(names):
        raise CampaignError("--summarize: the campaigns share cells (" + next(n for n in names if names.count(n) > 1)
                            + "): give each cell once")
    stains, bounds, felt, v_plan, pad = _bounds([c for c, _ in entries])
    rows = []
    for cell, run_dir in entries:
        report_path = Path(run_dir) / "report.json"
        report = json.loads(report_path.read_text()) if report_path.is_file() else None
        rows.append(row_of(cell, report, bounds[cell], run_dir, "" if report else "no report.json", stains[cell],
                           felt, v_plan))
    return _write_outputs(out, rows, command, {"pad_width_m": pad, "felt": felt, "planner_speed_m_s": v_plan,
                                               "from": [str(d) for d in dirs]})


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="lamps campaign", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9", help="seeds, e.g. 0-49 or 1,3,5-7 (default 0-9)")
    ap.add_argument("--stains", default="1-6", help="stain counts, cycled over the seeds (default 1-6)")
    ap.add_argument("--boards", default="wall,table",
                    help="boards, cycled over the seeds: wall, table or a board TOML file (lamps up --board), "
                         "comma-separated (default wall,table)")
    ap.add_argument("--wiping", default="fixed",
                    help="wiping modes, each seed runs once per mode: fixed, adaptive or fixed,adaptive (default "
                         "fixed, the controller's default)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="cells at once (default: the CPUs)")
    ap.add_argument("--skill", default=None, help="skill file (default: learn the bundled demo once)")
    ap.add_argument("--max-duration", type=float, default=600.0, help="give a cell up after S s wall (default 600)")
    ap.add_argument("--out", default=None, help="campaign folder (default runs/campaign-<time>)")
    ap.add_argument("--summarize", nargs="+", metavar="DIR", default=None,
                    help="run nothing: one table of these campaign folders' cells, into --out")
    ap.add_argument("-v", "--verbose", action="store_true", help="log what the campaign does")
    return ap


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps campaign %(levelname)s: %(message)s")
    try:
        if a.summarize:
            if not a.out:
                raise CampaignError("--summarize needs --out (the folder of the joint table)")
            out = Path(a.out).resolve()
            command = "lamps campaign " + " ".join(argv if argv is not None else sys.argv[1:])
            result = summarize_campaigns([Path(d).resolve() for d in a.summarize], out, command)
            print(markdown(result["summary"], [], "").split("\n\n")[0])
            print(f"campaign: {out / 'campaign.md'}, {out / 'campaign.json'}, {out / 'campaign.png'}")
            return 0
        seeds, stains = parse_range(a.seeds, "seeds"), parse_range(a.stains, "stains")
        if 0 in stains:
            raise CampaignError(f"--stains {a.stains!r}: a cell needs at least one stain")
        boards = [b.strip() for b in a.boards.split(",") if b.strip()]
        for b in boards:
            if b not in BOARD_NAMES and not Path(b).is_file():
                raise CampaignError(f"--boards: {b!r} is not one of {BOARD_NAMES} and no such file")
        if a.jobs < 1:
            raise CampaignError(f"--jobs must be >= 1, got {a.jobs}")
        if not a.max_duration > 0:
            raise CampaignError(f"--max-duration must be > 0, got {a.max_duration}")
        skill = None
        if a.skill:
            skill = Path(a.skill).resolve()
            if not skill.is_file():
                raise CampaignError(f"--skill {a.skill}: no such file")
        out = Path(a.out or f"runs/campaign-{time.strftime('%Y%m%d-%H%M%S')}").resolve()
        wipings = tuple(w.strip() for w in a.wiping.split(",") if w.strip())
        cells = cells_of(seeds, stains, boards, wipings)
        command = "lamps campaign " + " ".join(argv if argv is not None else sys.argv[1:])
        result = run_campaign(cells, out, a.jobs, skill, a.max_duration, command)
    except LampsError as exc:
        print(f"lamps campaign: error: {exc}", file=sys.stderr)
        return 1
    print(markdown(result["summary"], [], "").split("\n\n")[0])
    print(f"campaign: {out / 'campaign.md'}, {out / 'campaign.json'}, {out / 'campaign.png'}")
    missing = [c for c in result["cells"] if c["outcome"] == "no report"]
    if missing:
        print(f"lamps campaign: {len(missing)} cell(s) left no report: "
              + "; ".join(f"{c['name']}: {c['why']}" for c in missing[:3]), file=sys.stderr)
        return 1
    return 0
