"""A campaign's cells as Ray tasks: ``lamps campaign --ray [ADDRESS]``, one whole cell per task, on a Ray cluster.

No scheduler of our own: each cell is a Ray task (one CPU) that runs
:func:`launch.campaign_run.run_cell` (``lamps up`` in lock-step on ports of
its own) on whichever node Ray picks and returns the cell's report. The
skill travels with the task (its bytes, written on the worker), the
report comes back with the result and is written into the campaign
folder when the worker's disk is not the driver's. A worker lost while
it runs a cell (the node gone, the process killed) is Ray's to retry
(``max_retries``); a cell that runs and faults returned a report: it is a
result, never retried. ``ADDRESS`` is a running cluster (``ray start
--head`` prints it; ``auto`` finds the local one); without it a local
cluster is started for the campaign with ``--jobs`` CPUs.

Ray is an optional extra: ``pip install 'lamps[ray]'``.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterator
from pathlib import Path

from lampskit.atomic import write_text_atomic

from .campaign_cells import CampaignError, Cell

#: A cell's task is run again this often when its worker dies under it.
MAX_RETRIES = 2


def _cell_task(k: int, cell: Cell, skill_bytes: bytes, out: str, max_duration_s: float,
               port_base: int, network: bool = True) -> tuple[dict | None, str, str]:
    """On a Ray worker: the skill written locally, the cell run as the local campaign runs it."""
    import shutil

    from launch.campaign_run import run_cell

    run_dir = Path(out) / "cells" / cell.name
    if (run_dir / "report.json").is_file():  # a retry after the worker died once the cell had finished
        return json.loads((run_dir / "report.json").read_text()), str(run_dir), ""
    if run_dir.exists():  # a retry after the worker died under the cell: its half-run folder goes
        shutil.rmtree(run_dir)
    with tempfile.TemporaryDirectory(prefix="lamps-skill-") as tmp:
        skill = Path(tmp) / "skill.json"
        skill.write_bytes(skill_bytes)
        return run_cell(k, cell, skill, Path(out), max_duration_s, port_base, network)


def ray_cells(todo: list[int], cells: list[Cell], skill: Path, out: Path, max_duration_s: float, port_base: int,
              address: str, jobs: int, network: bool = True) -> Iterator[tuple[int, dict | None, str, str]]:
    """(k, report or None, run folder, why) of each cell of ``todo`` as its task finishes."""
    try:
        import ray
    except ImportError:
        raise CampaignError("--ray needs Ray: pip install 'lamps[ray]' (or ./run-tests, which installs it)") from None
    started_here = address == "local"
    try:
        if started_here:
            ray.init(num_cpus=jobs, include_dashboard=False, log_to_driver=False, configure_logging=False)
        else:
            ray.init(address=address, log_to_driver=False, configure_logging=False)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        raise CampaignError(f"--ray {address}: cannot join the Ray cluster ({exc})") from None
    try:
        task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES, retry_exceptions=False)(_cell_task)
        skill_bytes = skill.read_bytes()
        pending = {task.remote(k, cells[k], skill_bytes, str(out), max_duration_s, port_base, network): k
                   for k in todo}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            ref = ready[0]
            k = pending.pop(ref)
            try:
                report, run_dir, why = ray.get(ref)
            except ray.exceptions.RayError as exc:  # retries spent: the worker kept dying
                yield k, None, str(out / "cells" / cells[k].name), f"ray: {type(exc).__name__}"
                continue
            local = out / "cells" / cells[k].name / "report.json"
            if report is not None and not local.is_file():  # run on another node's disk
                local.parent.mkdir(parents=True, exist_ok=True)
                write_text_atomic(local, json.dumps(report, indent=1) + "\n")
            yield k, report, str(local.parent), why
    finally:
        ray.shutdown()  # a cluster started here stops; a joined one only loses this driver
