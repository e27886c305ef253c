"""``lamps record`` (the recorder service of the cell) and ``lamps report`` (rebuild a run's report).

``lamps record`` subscribes every key of the cell and writes
``DIR/recording.mcap`` (:mod:`launch.record`) until SIGTERM or Ctrl-C, then
``DIR/report.json`` and the plots (:mod:`launch.report`). ``lamps report``
rebuilds the report and plots of a run folder from its recording alone.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from pathlib import Path

from lampskit.errors import LampsError
from interfaces.priority import BACKGROUND, set_service_priority


def record_main(argv: list[str] | None = None) -> int:
    from interfaces.config import add_zenoh_options, load_config, zenoh_with_options

    p = argparse.ArgumentParser(prog="lamps record", description=(
        "Record every key of the cell into DIR/recording.mcap (opens in Foxglove) until stopped (SIGTERM or "
        "Ctrl-C); then write DIR/report.json and the plots."))
    p.add_argument("--out", required=True, metavar="DIR", help="run folder")
    p.add_argument("--config", metavar="FILE", help="TOML config with a [zenoh] table")
    p.add_argument("--no-report", action="store_true", help="only the recording")
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    add_zenoh_options(p)
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING,
                        format="lamps record %(levelname)s: %(message)s")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        settings = zenoh_with_options(load_config(a.config).zenoh, a)
        set_service_priority(BACKGROUND)
        from interfaces.session import ServiceNode

        from .record import Recorder

        node = ServiceNode("recorder", settings).__enter__()
    except LampsError as exc:
        print(f"lamps record: error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # zenoh's own error type for a bad endpoint
        print(f"lamps record: error: cannot open the Zenoh session ({exc})", file=sys.stderr)
        return 1
    out = Path(a.out)
    try:
        rec = Recorder(node.session, settings.keys, out)
        stop.wait()
        path = rec.close()
    finally:
        node.close()
    print(f"recorded {sum(rec.counters.values())} messages into {path}", flush=True)
    if a.no_report:
        return 0
    return _write_report(out, settings.keys)


def _write_report(out: Path, keys=None) -> int:
    from .report import summary_lines, write_report

    try:
        report = write_report(out, keys=keys)
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
    return _write_report(run)
