"""``lamps bench``: every benchmark of the project, one after the other, into one JSON file and one markdown page.

Each script in ``bench/`` (a source checkout) runs in its own process with
``--json`` (and ``--quick`` if asked); its markdown tables (stdout) go into
``bench.md`` under its name and its figures into ``bench.json`` under its
name, with the machine, the commit and the command that reproduces it. The
README's results tables are copied from ``bench.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lampskit.atomic import write_text_atomic

BENCH_DIR = Path(__file__).resolve().parent.parent / "bench"
#: The benchmarks in the order they run (cheap ones first).
SCRIPTS = ("bench_periodic_step", "bench_transitional_step", "bench_planner", "bench_look_points",
           "bench_loop_additions", "bench_segmentation", "eval_segmentation_accuracy", "bench_sim",
           "bench_sim_armature", "bench_controller", "bench_robot_port", "bench_zenoh_security", "bench_perception")


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=BENCH_DIR.parent, capture_output=True,
                              text=True, timeout=10).stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="lamps bench", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="bench-results", metavar="DIR", help="where bench.json and bench.md go")
    p.add_argument("--quick", action="store_true", help="the scripts' short runs (a smoke test, not for the README)")
    p.add_argument("--only", action="append", choices=SCRIPTS, help="run only this benchmark (repeatable)")
    a = p.parse_args(argv)
    if not BENCH_DIR.is_dir():
        print(f"lamps bench: error: the benchmarks live in a source checkout ({BENCH_DIR} is missing)", file=sys.stderr)
        return 1
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    results: dict = {"machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
                     "commit": _commit(), "quick": a.quick, "benchmarks": {}}
    pages = [f"# LAMPS benchmarks\n\n{results['machine']}, commit {results['commit']}"
             f"{' (quick runs)' if a.quick else ''}; `lamps bench{' --quick' if a.quick else ''}`\n"]
    failed = []
    for name in a.only or SCRIPTS:
        script = BENCH_DIR / f"{name}.py"
        with tempfile.TemporaryDirectory() as tmp:
            js = Path(tmp) / "out.json"
            cmd = [sys.executable, str(script), "--json", str(js)] + (["--quick"] if a.quick else [])
            print(f"lamps bench: {name} ...", flush=True)
            t0 = time.monotonic()
            r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
            wall = time.monotonic() - t0
            entry = {"command": f"python bench/{name}.py" + (" --quick" if a.quick else ""), "wall_s": round(wall, 1),
                     "exit_code": r.returncode}
            if r.returncode != 0:
                failed.append(name)
                entry["error"] = (r.stderr.strip().splitlines() or ["(no output)"])[-1]
                print(f"lamps bench: {name} failed: {entry['error']}", file=sys.stderr)
            elif js.is_file():
                entry["result"] = json.loads(js.read_text())
        results["benchmarks"][name] = entry
        pages.append(f"\n## {name}\n\n`{entry['command']}` ({wall:.0f} s)\n\n{r.stdout.strip()}\n")
        write_text_atomic(out / "bench.json", json.dumps(results, indent=1) + "\n")
        write_text_atomic(out / "bench.md", "".join(pages))
    print(f"lamps bench: wrote {out / 'bench.json'} and {out / 'bench.md'}")
    if failed:
        print(f"lamps bench: error: {', '.join(failed)} failed", file=sys.stderr)
        return 1
    return 0
