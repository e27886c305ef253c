"""A campaign of seeded cells: many boards run whole, several at once, summed up in a table and plots.

``lamps campaign --seeds 0-49 --stains 1-6 --boards wall,table,config/boards/tilted.toml --wiping fixed,adaptive``

Cell k runs seed ``s`` (the k-th of ``--seeds``) with ``lo + s mod (hi - lo + 1)``
stains of ``--stains lo-hi`` on board ``boards[s mod len(boards)]``, so every board
and every stain count is covered in turn and a cell is the same whatever else
the campaign holds; each seed runs once per ``--wiping`` mode (``fixed``: the
periodic MP set once per stain; ``adaptive``: shaped to the stain and
following its ink, ``[controller.planner] adaptive``). Each cell is ``lamps up`` in lock-step (deterministic for
its seed) with the skill learned once, in its own run folder under
``OUT/cells/``; up to ``--jobs`` run at once, each on its own ports (or, with
``--ray [ADDRESS]``, as tasks on a Ray cluster: :mod:`launch.campaign_ray`).

From each cell's ``report.json``: outcome, dirt removed, robot time (to the
DONE the run ended in, ``job_end_s``; the cell time, ``sim_time_s``, also
counts the launcher's 2.5 s look that DONE holds, and is kept beside it), peak
contact force, peak jerk of the executed reference, faults, and a **lower
bound** on the robot time (:func:`~launch.campaign_bounds.lower_bound_s`): the stains' dirt area swept
by the pad's long side at the controller's Cartesian speed limit, plus the
shortest network joining the stains (a minimum spanning tree, no longer than
any path through them) at that speed. That bound leaves out everything a run
does besides sweeping and travelling, so a second one, the **cell bound**
(:func:`~launch.campaign_bounds.cell_bound_s`), adds the run's fixed moves as it executed them (the
robot time before the skill's first transition: waiting for the peers, the
survey's flight and look, the approach, touch-down and force ramp; and the
RETREAT phase: ramp-out, lift-off, flight back; the same whatever the
wiping) and counts
the sliding the felt needs (:func:`~launch.campaign_bounds.felt_path_m`) at the planner's speed
bound. A cell *succeeds* when it removed at least :data:`~launch.campaign_table.CLEAN_SHARE` of its
dirt and nothing faulted.

Writes ``campaign.json`` (every cell, the summary), ``campaign.md`` (the table
per board and wiping mode, and over all) and ``campaign.png`` (robot time
against the lower bound, dirt removed per cell), each atomically, again
after every cell: the table grows as cells finish, and each finished cell
prints the progress (cells done, failed, time taken and left). A campaign
stopped half-way keeps what it finished; ``--resume`` with the same
``--out`` (and options) runs only the cells without a report, and again the
cells the stop cut short (``run.json``'s outcome ``stopped``: their report
shows the stop, :func:`launch.campaign_run.finished_report`); the table
alone (``campaign.json`` carried to another machine) keeps its cells too. Exit 0 when
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
import shutil
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from lampskit.atomic import write_text_atomic
from lampskit.errors import LampsError

from .campaign_bounds import lower_bound_s
from .campaign_cells import CampaignError, Cell, cells_of, parse_range
from .campaign_pool import WorkerPool
from .campaign_run import PORT_BASES, finished_report, run_cell
from .campaign_table import CLEAN_SHARE, markdown, plot, row_of, summarize

BOARD_NAMES = ("wall", "table", "vertical", "horizontal")
log = logging.getLogger(__name__)


def felt_model() -> dict[str, float]:
    """The sim's removal law at the controller's wiping force, and the report's level of a wiped stain."""
    from arm.description import PAD_SIZE_M
    from controller.params import ControllerParams
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
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "demo", "--stains", "3", "--seed", "0", "--out",
                        str(learn)], capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
    if r.returncode != 0 or not (learn / "skill.json").is_file():
        raise CampaignError(f"learning the skill failed (exit {r.returncode}): {r.stderr.strip()[-300:]}")
    return learn / "skill.json"


class _Bounds:
    """Each cell's stains (areas, centres) and lower bound, worked out the first time the cell's row is made (a
    random board's table is sampled for it, 0.3-3 s): a campaign's workers start on their first cells at once, and a
    resumed campaign samples no board of a row it keeps from its table. Also the felt model, the planner's speed
    bound and the pad's width."""

    def __init__(self, cells: list[Cell]) -> None:
        from arm.description import PAD_SIZE_M
        from controller.params import ControllerParams
        from lampskit.core.planner_types import PlannerParams

        self.speed, self.pad = ControllerParams.from_table({}).limits.max_speed_m_s, max(PAD_SIZE_M)
        self.felt, self.v_plan = felt_model(), PlannerParams().max_speed_m_s
        self._tables: dict[str, dict[str, Any]] = {}
        self._cells: dict[Cell, tuple[tuple[list[float], np.ndarray], float]] = {}
        for b in dict.fromkeys(c.board for c in cells if not c.board.startswith("random:")):
            self._tables[b] = _board_table(b)  # a board file that cannot be read: refused before any cell runs

    def of(self, cell: Cell) -> tuple[tuple[list[float], np.ndarray], float]:
        """(``cell``'s stains, its lower bound [s])."""
        if cell not in self._cells:
            if cell.board not in self._tables:
                self._tables[cell.board] = _board_table(cell.board)
            stains = cell_stains(cell, self._tables[cell.board])
            self._cells[cell] = stains, lower_bound_s(*stains, self.pad, self.speed)
        return self._cells[cell]

    def row(self, cell: Cell, report: dict | None, run_dir: str, why: str) -> dict[str, Any]:
        """``cell``'s row of the table (:func:`launch.campaign_table.row_of`)."""
        stains, bound = self.of(cell)
        return row_of(cell, report, bound, run_dir, why, stains, self.felt, self.v_plan)


def _write_outputs(out: Path, rows: list[dict[str, Any]], command: str, extra: dict[str, Any]) -> dict[str, Any]:
    summary = summarize(rows)
    result = {"schema": "lamps-campaign/1", "command": command, "clean_share": CLEAN_SHARE, **extra,
              "summary": summary, "cells": rows}
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "campaign.json", json.dumps(result, indent=1) + "\n")
    write_text_atomic(out / "campaign.md", markdown(summary, rows, command))
    plot(rows, out / "campaign.png")
    return result


def _local_cells(todo: list[int], cells: list[Cell], skill: Path, out: Path, max_duration_s: float, port_base: int,
                 jobs: int, network: bool):
    """(k, report or None, run folder, why) of each cell of ``todo`` as it finishes, ``jobs`` at once here: each a
    ``lamps up`` process, or (not ``network``) in ``jobs`` long-lived workers (:mod:`launch.campaign_pool`)."""
    with WorkerPool() as workers, concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
        if network:
            futures = {pool.submit(run_cell, k, cells[k], skill, out, max_duration_s, port_base, network): k
                       for k in todo}
        else:
            futures = {pool.submit(workers.run_cell, k, cells[k], skill, out, max_duration_s): k for k in todo}
        for fut in concurrent.futures.as_completed(futures):
            yield (futures[fut], *fut.result())


def _say(line: str) -> None:
    print(line, flush=True)  # progress seen as it happens, also through a pipe or into a log


def _tabled_rows(out: Path, cells: list[Cell]) -> dict[str, dict[str, Any]]:
    """The finished cells of ``out/campaign.json`` by name ({} without the file): a resumed campaign keeps these
    rows when their cell folders are gone (the table carried to another machine without the recordings), and for a
    folder that holds its report a row made from that folder (no random board sampled again, 0.3-3 s each).
    :class:`CampaignError` for a table that cannot be read or a row that is not the cell its name says."""
    path = out / "campaign.json"
    if not path.is_file():
        return {}
    try:
        rows = {str(r["name"]): r for r in json.loads(path.read_text())["cells"] if r["outcome"] != "no report"}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CampaignError(f"--resume: cannot read the table {path}: {exc}") from None
    for c in (c for c in cells if c.name in rows):
        wrong = [f"{f} {rows[c.name].get(f)!r}" for f, v in asdict(c).items()
                 if f != "plots" and rows[c.name].get(f) != v]
        if wrong:
            raise CampaignError(f"--resume: the row {c.name} of {path} is another cell ({', '.join(wrong)})")
    return rows


def run_campaign(cells: list[Cell], out: Path, jobs: int, skill: Path | None, max_duration_s: float,
                 command: str, echo=_say, resume: bool = False, ray: str | None = None,
                 network: bool = True) -> dict[str, Any]:
    """Run every cell (``jobs`` at once), write campaign.json, .md and .png into ``out`` after each cell (the table
    grows as cells finish); returns the json. ``resume``: the cells whose run folder holds the report of a cell
    that ran to its end are taken as they are (their row of the table, else one made from the report), a cell
    folder without one (a campaign killed or stopped while it ran) is run again, a cell without a folder but with a
    row in ``out/campaign.json`` keeps that row (:func:`_tabled_rows`), the rest run. ``ray``:
    run the cells as tasks on that Ray cluster (``local``: one started here), :mod:`launch.campaign_ray`.
    ``network``: each cell over Zenoh (``lamps up``); False: in one process without one (``--no-network``)."""
    out.mkdir(parents=True, exist_ok=True)
    bounds = _Bounds(cells)
    rows: list[dict[str, Any] | None] = [None] * len(cells)
    todo = []
    only_table = 0
    tabled = _tabled_rows(out, cells) if resume else {}
    for k, c in enumerate(cells):
        run_dir = out / "cells" / c.name
        report = finished_report(run_dir)[0] if resume else None
        if report is not None:
            kept = tabled.get(c.name)  # the row its report made when it finished: no board sampled again
            rows[k] = kept if kept is not None and kept.get("run_dir") == str(run_dir) \
                else bounds.row(c, report, str(run_dir), "")
            continue
        if not run_dir.exists() and c.name in tabled:
            rows[k] = tabled[c.name]  # its folder stayed on the machine that ran it
            only_table += 1
            continue
        if run_dir.exists():
            if not resume:
                raise CampaignError(f"{run_dir} exists: a campaign folder is never overwritten (--resume runs only "
                                    "the cells that left no report)")
            shutil.rmtree(run_dir)  # a cell killed half-way: run again from the start
        todo.append(k)
    learned = out / "learn" / "skill.json"
    skill = skill or (learned if resume and learned.is_file() else _learn_skill(out))
    extra = {"pad_width_m": bounds.pad, "felt": bounds.felt, "planner_speed_m_s": bounds.v_plan, "network": network}
    if resume:
        echo(f"resuming: {len(cells) - len(todo)} of {len(cells)} cells already have a report "
             f"({only_table} of them only in the table), "
             f"{len(todo)} to run")
    t0 = time.monotonic()
    finished = failed = 0
    port_base = random.choice(PORT_BASES)
    if ray is not None:
        from .campaign_ray import ray_cells

        results = ray_cells(todo, cells, skill, out, max_duration_s, port_base, ray, jobs, network)
    else:
        results = _local_cells(todo, cells, skill, out, max_duration_s, port_base, jobs, network)
    for k, report, cell_dir, why in results:
        rows[k] = r = bounds.row(cells[k], report, cell_dir, why)
        finished += 1
        failed += not r["success"]
        _write_outputs(out, [x for x in rows if x is not None], command, extra)
        elapsed = time.monotonic() - t0
        left = (len(todo) - finished) * elapsed / finished
        echo(f"[{sum(x is not None for x in rows)}/{len(cells)} done, {failed} failed, {elapsed:.0f} s, "
             f"~{left:.0f} s left] {cells[k].name}: "
             + (f"no report ({why})" if report is None else
                f"{r['outcome']}, {r['dirt_removed']:.1%} removed in {r['robot_time_s']:.1f} s "
                f"({r['time_over_cell_bound']:.2f}x the cell bound)"))
    done = [r for r in rows if r is not None]
    return _write_outputs(out, done, command, extra)


def summarize_campaigns(dirs: list[Path], out: Path, command: str) -> dict[str, Any]:
    """One table of earlier campaigns' cells (``DIR/campaign.json``), each cell's ``report.json`` as it is now
    (rebuilt by ``lamps report`` after the report gained a field, say) and today's bounds."""
    entries = []
    for d in dirs:
        path = d / "campaign.json"
        try:
            data = json.loads(path.read_text())
            cells = [(Cell(int(c["seed"]), int(c["stains"]), str(c["board"]), str(c.get("wiping", "fixed")),
                           plant=str(c.get("plant", "nominal"))), str(c["run_dir"])) for c in data["cells"]]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise CampaignError(f"--summarize {d}: cannot read {path.name}: {exc}") from None
        entries += cells
    names = [c.name for c, _ in entries]
    if len(set(names)) != len(names):
        raise CampaignError("--summarize: the campaigns share cells (" + next(n for n in names if names.count(n) > 1)
                            + "): give each cell once")
    bounds = _Bounds([c for c, _ in entries])
    rows = []
    for cell, run_dir in entries:
        report_path = Path(run_dir) / "report.json"
        report = json.loads(report_path.read_text()) if report_path.is_file() else None
        rows.append(bounds.row(cell, report, run_dir, "" if report else "no report.json"))
    return _write_outputs(out, rows, command, {"pad_width_m": bounds.pad, "felt": bounds.felt,
                                               "planner_speed_m_s": bounds.v_plan,
                                               "from": [str(d) for d in dirs]})


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="lamps campaign", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9", help="seeds, e.g. 0-49 or 1,3,5-7 (default 0-9)")
    ap.add_argument("--stains", default="1-6", help="stain counts, cycled over the seeds (default 1-6)")
    ap.add_argument("--boards", default="wall,table",
                    help="boards, cycled over the seeds: wall, table, random (seed s: the reachable board lamps up "
                         "--board random:s draws) or a board TOML file (lamps up --board), "
                         "comma-separated (default wall,table)")
    ap.add_argument("--wiping", default="fixed",
                    help="wiping modes, each seed runs once per mode: fixed, adaptive or fixed,adaptive (default "
                         "fixed, the controller's default)")
    ap.add_argument("--plants", default="nominal",
                    help="simulated arms, each seed runs once per plant: nominal (the description), stuerz2017 (the "
                         "link masses identified on a real iiwa 14), random (links +-30 %% in mass and inertia, "
                         "centres of mass up to 2 cm off, seeded), tool (an unknown 0.2-1.5 kg tool, seeded), "
                         "arm (random and tool at once); "
                         "comma-separated (default nominal; the controller always keeps the description)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="cells at once (default: the CPUs)")
    ap.add_argument("--skill", default=None, help="skill file (default: learn the bundled demo once)")
    ap.add_argument("--max-duration", type=float, default=600.0, help="give a cell up after S s wall (default 600)")
    ap.add_argument("--out", default=None, help="campaign folder (default runs/campaign-<time>)")
    ap.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                    help="run the cells as Ray tasks on the cluster at ADDRESS (ray start --head prints it; 'auto': "
                         "the local one); without ADDRESS a local cluster of --jobs CPUs (needs lamps[ray])")
    ap.add_argument("--no-network", action="store_true",
                    help="each cell in one process without Zenoh (lamps up --no-network: the same services, stepped "
                         "in lock-step on an in-process bus); default: each cell over Zenoh as lamps up runs it")
    ap.add_argument("--cell-plots", action="store_true",
                    help="each cell's report also draws its plots (default: report.json only; lamps report "
                         "CELL_DIR draws them later from the cell's recording)")
    ap.add_argument("--resume", action="store_true",
                    help="--out is a campaign that was stopped: keep the cells that left a report (or, their folders "
                         "gone, a row in its campaign.json), run the rest")
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
            if b not in BOARD_NAMES and b != "random" and not Path(b).is_file():
                raise CampaignError(f"--boards: {b!r} is not one of {(*BOARD_NAMES, 'random')} and no such file")
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
        plants = tuple(p.strip() for p in a.plants.split(",") if p.strip())
        cells = cells_of(seeds, stains, boards, wipings, plots=a.cell_plots, plants=plants)
        command = "lamps campaign " + " ".join(argv if argv is not None else sys.argv[1:])
        if a.resume and not (a.out and Path(a.out).is_dir()):
            raise CampaignError("--resume needs --out, the folder of the campaign to go on with")
        result = run_campaign(cells, out, a.jobs, skill, a.max_duration, command, resume=a.resume, ray=a.ray,
                              network=not a.no_network)
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
