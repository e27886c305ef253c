"""``lamps record`` (the recorder service of the cell) and ``lamps report`` (rebuild a run's report).

``lamps record`` subscribes every key of the cell and writes
``DIR/recording.mcap`` (:mod:`launch.record`) until SIGTERM or Ctrl-C, then
``DIR/report.json`` and the plots (:mod:`launch.report`); with ``--until
done`` it also ends by itself once the controller is DONE (or stays in
FAULT / ESTOP), exiting 0 only when the report says cleaned, so
``docker compose up --exit-code-from recorder`` runs one job and says how it
went. ``lamps record --cells ID,...`` records a site instead: every cell's keys, as the site viewer through
the site's router, into one recording (no report: each cell's own recorder writes its own). ``lamps report``
rebuilds the report and plots of a run folder from its recording alone.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from pathlib import Path


def record_main(argv: list[str] | None = None) -> int:
    from runtime.config import add_zenoh_options

    p = argparse.ArgumentParser(prog="lamps record", description=(
        "Record every key of the cell into DIR/recording.mcap (opens in Foxglove) until stopped (SIGTERM or "
        "Ctrl-C); then write DIR/report.json and the plots."))
    p.add_argument("--out", required=True, metavar="DIR", help="run folder")
    p.add_argument("--config", metavar="FILE", help="TOML config with a [zenoh] table")
    p.add_argument("--no-report", action="store_true", help="only the recording")
    p.add_argument("--until", choices=("stopped", "done"), default="stopped",
                   help="stopped: record until SIGTERM / Ctrl-C (default); done: also end once the controller is "
                        "DONE (or in FAULT / ESTOP), exit 0 only if the report says cleaned")
    p.add_argument("--max-duration", type=float, default=None, metavar="S",
                   help="with --until done: end after S seconds (wall) whatever the controller does")
    p.add_argument("--cells", metavar="ID,...", help="record every one of these cells (robot ids) of a site into "
                   "one file, as the site viewer ([zenoh] cells); only the recording")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    add_zenoh_options(p)
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps record %(levelname)s: %(message)s")
    from .background_node import cells_option

    try:
        cells = cells_option(a)
    except ValueError as exc:
        p.error(str(exc))
    if cells and a.until == "done":
        p.error("--until done follows one cell's controller: not with --cells")
    if a.max_duration is not None and not (a.max_duration > 0 and a.max_duration < float("inf")):
        p.error(f"--max-duration must be a positive number of seconds, got {a.max_duration}")
    from runtime.stop_signals import wait_for

    from .background_node import open_background_node
    from .record import Recorder, budget_from_env

    try:
        budget = budget_from_env()
    except ValueError as exc:
        print(f"lamps record: error: {exc}", file=sys.stderr)
        return 1
    opened = open_background_node("lamps record", "recorder", a, cells)
    if opened is None:
        return 1
    node, settings, stop = opened
    out = Path(a.out)
    from interfaces.keys import Keys

    try:
        rec = Recorder(node.session, [Keys.for_robot(c) for c in settings.cells] or settings.keys, out,
                       budget_bytes=budget)
        ended = _wait_for_end(node, stop, a.max_duration) if a.until == "done" else (wait_for(stop), None)[1]
        path = rec.close()
    finally:
        node.close()
    accounts = rec.budget.accounts.values()
    dropped = sum(sum(a.dropped.values()) for a in accounts)
    print(f"recorded {sum(a.recorded for a in accounts)} messages into {path}"
          + (f", dropped {dropped} (recorder/status says of which keys and why)" if dropped else "")
          + (f"; the run ended: {ended[1]}" if ended else ""), flush=True)
    if a.no_report or settings.cells:
        return 0
    code = _write_report(out, settings.keys)
    if a.until == "done" and code == 0:
        import json

        outcome = json.loads((out / "report.json").read_text()).get("outcome")
        if outcome != "cleaned":
            print(f"lamps record: the board was not cleaned ({outcome})", file=sys.stderr)
            return 3
    return code


def _wait_for_end(node, stop: threading.Event, max_duration_s: float | None) -> tuple[str, str] | None:
    """Until stopped (None), or the run's end as :class:`launch.run_end.RunEnd` judges it (outcome, why)."""
    import time

    from interfaces.messages import ControllerStatus

    from .run_end import RunEnd

    status = node.latest(node.keys.controller_status, ControllerStatus)
    end, t0, st = RunEnd(), time.monotonic(), None
    while not stop.wait(0.1):
        now = time.monotonic()
        if max_duration_s is not None and now - t0 > max_duration_s:
            return "timeout", f"not finished after --max-duration {max_duration_s:g} s"
        st = status.take() or st
        if st is not None:
            ended = end.update(st.phase, st.reason, now, st.robot_time_ns * 1e-9)
            if ended is not None:
                return ended
    return None


def _write_report(out: Path, keys=None, plots: bool | None = None) -> int:
    from .report import summary_lines, write_report

    try:
        report = write_report(out, keys=keys, plots=plots)
    except Exception as exc:  # a report must never lose the recording: say why and keep it
        print(f"lamps report: error: cannot build the report of {out}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    for line in summary_lines(report):
        print(line, flush=True)
    return 0


def report_main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="lamps report", description=(
        "Rebuild RUN_DIR/report.json and the plots from RUN_DIR/recording.mcap (and run.json if present); a run "
        "whose recorder died (only recording.mcap.partial) is recovered first, up to the crash."))
    p.add_argument("run_dir", metavar="RUN_DIR")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps report %(levelname)s: %(message)s")
    from .record import RECORDING, recover_recording

    run = Path(a.run_dir)
    final, partial = run / RECORDING, run / (RECORDING + ".partial")
    if not final.is_file() and partial.is_file():  # the recorder died: keep what reached the disk
        try:
            n = recover_recording(partial, final)
        except OSError as exc:
            print(f"lamps report: error: cannot recover {partial}: {exc}", file=sys.stderr)
            return 1
        print(f"lamps report: the recorder did not finish; recovered {n} messages from {partial.name} into "
              f"{final.name}", flush=True)
    if not final.is_file():
        print(f"lamps report: error: {run}: no {RECORDING} (is this a run folder?)", file=sys.stderr)
        return 1
    return _write_report(run, plots=True)
