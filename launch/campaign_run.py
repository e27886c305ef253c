"""One cell of a campaign run as ``lamps up`` in lock-step, on ports of its own or (``network=False``) in one process
without a network (``lamps up --no-network``, :mod:`launch.local_cell`): a Ray task's work (:mod:`launch.campaign`,
:mod:`launch.campaign_ray`); the thread pool runs network-free cells in :mod:`launch.campaign_pool`'s workers with
the same arguments and environment (:func:`up_argv`, :func:`cell_env`)."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

from .campaign_cells import Cell

#: Cell k listens on ports from base + (k mod PORT_SLOTS) * PORT_STRIDE (a cell uses fewer than 10), base one of
#: PORT_BASES picked per campaign (ports a campaign just closed stay unbindable for a minute); a busy port moves
#: the cell PORT_SLOTS * PORT_STRIDE up. All below the kernel's ephemeral range (32768).
PORT_BASES, PORT_SLOTS, PORT_STRIDE = (20000, 23000, 26000), 100, 10

log = logging.getLogger("launch.campaign")


def up_argv(cell: Cell, skill: Path, run_dir: Path, max_duration_s: float, port_base: int | None) -> list[str]:
    """``lamps up``'s arguments for ``cell`` in lock-step: on ports from ``port_base``, or (None) without a
    network."""
    return ["--seed", str(cell.seed), "--stains", str(cell.stains), "--board", cell.board, "--skill", str(skill),
            "--out", str(run_dir), "--mode", "lockstep", "--max-duration", str(max_duration_s), "-q",
            *(("--port-base", str(port_base)) if port_base is not None else ("--no-network",))]


def cell_env(cell: Cell) -> dict[str, str]:
    """What the cell adds to the campaign's environment: its wiping mode, its plant (the simulator's
    ``[sim.plant]``, :func:`launch.campaign_plants.plant_env`), whether its report draws plots
    (:data:`launch.report_options.PLOTS_ENV`), plots without a display."""
    from .campaign_plants import plant_env
    from .report_options import PLOTS_ENV

    return {"MPLBACKEND": "Agg", PLOTS_ENV: "1" if cell.plots else "0",
            "LAMPS__CONTROLLER__PLANNER__ADAPTIVE": "true" if cell.wiping == "adaptive" else "false",
            **plant_env(cell.plant, cell.seed)}


def why_of(stderr: str, code: int) -> str:
    """Why a cell left no report: the last line it wrote to stderr, else its exit code."""
    return (stderr.strip().splitlines() or [f"exit {code}"])[-1]


def finished_report(run_dir: Path) -> tuple[dict | None, str]:
    """(the report of the cell in ``run_dir``, "") when it ran to its own end; (None, why) when it left no report
    or was stopped from outside (``run.json``'s outcome ``stopped``: a SIGTERM or Ctrl-C to the campaign, its worker
    or the cell). A stopped cell's report says what the stop did (a pad lifted off mid-wipe is an ESTOP), not what
    the cell does: it is no result, and ``--resume`` runs the cell again."""
    report, ran = run_dir / "report.json", run_dir / "run.json"
    if not report.is_file():
        return None, ""
    try:
        ended = json.loads(ran.read_text()).get("outcome") if ran.is_file() else None
    except (OSError, ValueError):
        ended = None
    if ended == "stopped":
        return None, "stopped from outside before its end (run.json: stopped); --resume runs it again"
    return json.loads(report.read_text()), ""


def run_cell(k: int, cell: Cell, skill: Path, out: Path, max_duration_s: float,
             port_base: int, network: bool = True) -> tuple[dict | None, str, str]:
    """``lamps up`` for one cell: (its report or None, its run folder, why there is none)."""
    run_dir = out / "cells" / cell.name
    base = port_base + (k % PORT_SLOTS) * PORT_STRIDE
    why = ""
    for attempt in range(3):  # a port taken by something else: again on another range
        ports = base + attempt * PORT_SLOTS * PORT_STRIDE if network else None
        argv = [sys.executable, "-m", "runtime.cli", "up", *up_argv(cell, skill, run_dir, max_duration_s, ports)]
        log.info("cell %s: %s", cell.name, " ".join(argv[2:]))
        r = subprocess.run(argv, capture_output=True, text=True, env={**os.environ, **cell_env(cell)},
                           timeout=max_duration_s + 120)
        report, stopped = finished_report(run_dir)
        if report is not None or stopped:
            return report, str(run_dir), stopped
        why = why_of(r.stderr, r.returncode)
        if not network or "already in use" not in why:
            break
    return None, str(run_dir), why
