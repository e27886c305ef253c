"""A campaign's worker: network-free cells one after another in one long-lived process (``python -m
launch.campaign_worker``, started by :mod:`launch.campaign_pool`).

A cell here is ``lamps up --no-network`` called in this process
(:func:`launch.cli.up_main`, the same arguments and environment as the
subprocess a Ray task starts, :func:`~launch.campaign_run.up_argv`,
:func:`~launch.campaign_run.cell_env`), so it builds every service, its
bus and recorder afresh and writes the same run folder; what stays
between cells is what a process pays for once: the interpreter, the
imports, the compiled numba kernels, and the camera's renderer process
when the next cell has the same scene (:func:`sim.renderer.keep_renderers`:
a frame is drawn from its request alone). Between cells the garbage is
collected and what is left is frozen (``gc.freeze``), so the next cell's
collections do not walk the imported modules again.

Protocol: one JSON object per line on stdin, ``{"seed", "stains",
"board", "wiping", "plots", "skill", "run_dir", "max_duration_s"}``; one JSON line
back per cell, ``{"code": exit code of lamps up, "why": its last line on
stderr}``, on the stdout the worker had when it started (anything else
written to stdout, by a C library say, goes to stderr). End of stdin ends
the worker. A cell that raises what ``lamps up`` would crash on is
answered and the worker exits (code 1), so no cell inherits a half-closed
one's state.
"""

from __future__ import annotations

import contextlib
import gc
import io
import json
import logging
import os
import sys
from pathlib import Path

from .campaign_cells import Cell
from .campaign_run import cell_env, up_argv, why_of


class _StderrNow(logging.StreamHandler):
    """Log records to whatever ``sys.stderr`` is when they are emitted (a cell's captured stderr)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass


#: The worker's environment as it started (a cell's variables are set on top of it, never on a cell's before).
_WORKER_ENV = dict(os.environ)


def run_here(cell: Cell, skill: Path, run_dir: Path, max_duration_s: float) -> tuple[int, str, bool]:
    """``lamps up --no-network`` for ``cell`` in this process: (exit code, its last stderr line, whether it
    crashed: raised what would have ended a ``lamps up`` process)."""
    from .cli import up_main

    os.environ.clear()  # the worker's own environment and this cell's: nothing left from the cell before
    os.environ.update(_WORKER_ENV)
    os.environ.update(cell_env(cell))
    err = io.StringIO()
    crashed = False
    with open(os.devnull, "w") as devnull, contextlib.redirect_stdout(devnull), contextlib.redirect_stderr(err):
        try:
            code = up_main(up_argv(cell, skill, run_dir, max_duration_s, None))
        except Exception as exc:  # a bug: a lamps up process would end with its traceback
            code, crashed = 1, True
            print(f"{type(exc).__name__}: {exc}", file=err)
    return code, why_of(err.getvalue(), code), crashed


def _end_with_the_campaign() -> None:
    """Linux: have the kernel send this worker SIGTERM when the campaign that started it dies (killed, crashed), as
    its cell's own stop would: a worker left behind runs its cell on for minutes, on cores nobody asked for. End of
    stdin still ends an idle worker everywhere."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # no prctl: only stdin's end stops it
        return
    if os.getppid() == 1:  # the campaign died before the request: nobody will send it
        sys.exit(0)


def main() -> int:
    from sim.renderer import keep_renderers

    _end_with_the_campaign()
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    logging.basicConfig(level=logging.WARNING, format="lamps up %(levelname)s: %(message)s", handlers=[_StderrNow()])
    keep_renderers()
    try:
        for line in sys.stdin:
            job = json.loads(line)
            cell = Cell(int(job["seed"]), int(job["stains"]), str(job["board"]), str(job["wiping"]),
                        bool(job.get("plots", False)), str(job.get("plant", "nominal")))
            code, why, crashed = run_here(cell, Path(job["skill"]), Path(job["run_dir"]), float(job["max_duration_s"]))
            answers.write(json.dumps({"code": code, "why": why}) + "\n")
            if crashed:
                return 1
            gc.collect()
            gc.freeze()
    except KeyboardInterrupt:  # Ctrl-C between cells (the campaign stops too)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
