"""The thread pool's network-free cells: ``--jobs`` long-lived worker processes (:mod:`launch.campaign_worker`),
each running cell after cell.

A cell is ``lamps up --no-network`` in a worker as a subprocess would run
it (same arguments, environment and run folder), without a new process,
imports and compiled kernels per cell. A worker that dies under a cell
(killed, crashed) or gives no answer within ``--max-duration`` plus
:data:`ANSWER_GRACE_S` is stopped; that cell is a cell without a report,
with the worker's last words as the reason, and the next cell gets a new
worker. Workers end with the campaign (end of their stdin; killed with its
process group).
"""

from __future__ import annotations

import json
import logging
import os
import queue
import subprocess
import sys
import threading
from collections import deque
from pathlib import Path

from .campaign_cells import Cell
from .campaign_run import finished_report

#: A worker gets this long [s] beyond the cell's ``--max-duration`` to answer (as the subprocess per cell did).
ANSWER_GRACE_S = 120.0

log = logging.getLogger("launch.campaign")


class Worker:
    """One worker process: :meth:`run` a cell in it; :attr:`alive` until it died or was stopped."""

    def __init__(self) -> None:
        self._proc = subprocess.Popen([sys.executable, "-m", "launch.campaign_worker"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
                                      env={**os.environ, "MPLBACKEND": "Agg"})
        stdin, stdout, stderr = self._proc.stdin, self._proc.stdout, self._proc.stderr
        assert stdin is not None and stdout is not None and stderr is not None  # all three piped above
        self._stdin, self._stdout, self._stderr = stdin, stdout, stderr
        self._last_words: deque[str] = deque(maxlen=20)
        self._answers: queue.Queue[dict | None] = queue.Queue()
        threading.Thread(target=self._read_answers, daemon=True, name="campaign-worker-answers").start()
        threading.Thread(target=self._read_stderr, daemon=True, name="campaign-worker-stderr").start()

    @property
    def alive(self) -> bool:
        return self._proc.poll() is None

    def _read_answers(self) -> None:
        for line in self._stdout:
            try:
                self._answers.put(json.loads(line))
            except ValueError:
                self._last_words.append(line.rstrip())
        self._answers.put(None)  # end of output: the worker is gone

    def _read_stderr(self) -> None:
        for line in self._stderr:
            if line.strip():
                self._last_words.append(line.rstrip())

    def run(self, cell: Cell, skill: Path, run_dir: Path, max_duration_s: float) -> tuple[int | None, str]:
        """(``lamps up``'s exit code, its last stderr line) of ``cell``; (None, why) when the worker died under it
        or did not answer in time (then it is stopped)."""
        job = {"seed": cell.seed, "stains": cell.stains, "board": cell.board, "wiping": cell.wiping,
               "plots": cell.plots, "plant": cell.plant, "skill": str(skill), "run_dir": str(run_dir),
               "max_duration_s": max_duration_s}
        try:
            self._stdin.write(json.dumps(job) + "\n")
            self._stdin.flush()
            answer = self._answers.get(timeout=max_duration_s + ANSWER_GRACE_S)
        except (OSError, ValueError):  # its stdin closed: it died before the cell
            answer = None
        except queue.Empty:
            self.stop()
            return None, f"the campaign worker gave no answer within {max_duration_s + ANSWER_GRACE_S:g} s"
        if answer is None:
            code = self.stop()
            said = next((w for w in reversed(self._last_words) if w.strip()), "")
            return None, f"the campaign worker died under the cell (exit {code})" + (f": {said}" if said else "")
        return int(answer["code"]), str(answer["why"])

    def stop(self, timeout_s: float = 10.0) -> int | None:
        """End the worker (end of its input, then a kill); its exit code."""
        try:
            self._stdin.close()
        except OSError:
            pass
        try:
            return self._proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            return self._proc.wait()


class WorkerPool:
    """Up to ``jobs`` workers, each used by one thread at a time; :meth:`run_cell` is the thread pool's task."""

    def __init__(self) -> None:
        self._idle: queue.SimpleQueue[Worker] = queue.SimpleQueue()
        self._all: list[Worker] = []
        self._lock = threading.Lock()

    def _take(self) -> Worker:
        while True:
            try:
                worker = self._idle.get_nowait()
            except queue.Empty:
                break
            if worker.alive:  # one that died between cells is passed over
                return worker
        worker = Worker()
        with self._lock:
            self._all.append(worker)
        return worker

    def run_cell(self, k: int, cell: Cell, skill: Path, out: Path, max_duration_s: float) -> tuple[dict | None, str,
                                                                                                        str]:
        """(its report or None, its run folder, why there is none), as :func:`launch.campaign_run.run_cell`."""
        run_dir = out / "cells" / cell.name
        worker = self._take()
        log.info("cell %s (#%d) in a worker", cell.name, k)
        code, why = worker.run(cell, skill, run_dir, max_duration_s)
        if code is not None and worker.alive:
            self._idle.put(worker)
        report, stopped = finished_report(run_dir)
        return report, str(run_dir), "" if report is not None else (stopped or why)

    def close(self) -> None:
        with self._lock:
            workers, self._all = self._all, []
        for w in workers:
            w.stop()

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
