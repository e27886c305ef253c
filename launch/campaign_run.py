"""One cell of a campaign run as ``lamps up`` in lock-step, on ports of its own or (``network=False``) in one process
without a network (``lamps up --no-network``, :mod:`launch.local_cell`): the thread pool's and a Ray task's work
(:mod:`launch.campaign`, :mod:`launch.campaign_ray`)."""

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


def run_cell(k: int, cell: Cell, skill: Path, out: Path, max_duration_s: float,
             port_base: int, network: bool = True) -> tuple[dict | None, str, str]:
    """``lamps up`` for one cell: (its report or None, its run folder, why there is none)."""
    run_dir = out / "cells" / cell.name
    base = port_base + (k % PORT_SLOTS) * PORT_STRIDE
    why = ""
    for attempt in range(3):  # a port taken by something else: again on another range
        argv = [sys.executable, "-m", "interfaces.cli", "up", "--seed", str(cell.seed), "--stains", str(cell.stains),
                "--board", cell.board, "--skill", str(skill), "--out", str(run_dir), "--mode", "lockstep",
                "--max-duration", str(max_duration_s), "-q",
                *(("--port-base", str(base + attempt * PORT_SLOTS * PORT_STRIDE)) if network else ("--no-network",))]
        log.info("cell %s: %s", cell.name, " ".join(argv[2:]))
        env = {**os.environ, "MPLBACKEND": "Agg",
               "LAMPS__CONTROLLER__PLANNER__ADAPTIVE": "true" if cell.wiping == "adaptive" else "false"}
        r = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=max_duration_s + 120)
        report = run_dir / "report.json"
        if report.is_file():
            return json.loads(report.read_text()), str(run_dir), ""
        why = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
        if not network or "already in use" not in why:
            break
    return None, str(run_dir), why
