"""Campaign throughput: cells per hour on this machine, Zenoh cells and network-free ones, locally and on Ray, one run.

The same cells each time (``--seeds``, ``--stains`` cycled over them, the
wall board, fixed wiping, the bundled demo learned once): ``lamps campaign
--jobs 2`` with each cell over Zenoh (``lamps up`` in lock-step: the
baseline), then ``--no-network`` (each cell in one process without a
network, :mod:`launch.local_cell`) on the local thread pool, and on a local
Ray cluster started for the campaign with 1 and 2 CPUs (``--ray --jobs 1``,
``--jobs 2``; Ray's token authentication on). Prints wall time, cells per
hour, the ratio to the baseline, whether every cell gave the same outcome
and dirt removed (within 0.5 points) as the baseline's, the largest
difference in dirt removed, and the CPU time the campaign and its children
used per cell (thread pool rows: Ray's workers are not the campaign's children).

Run: ``.venv/bin/python bench/bench_campaign.py [--seeds 0-9] [--stains 1-3]`` (about 20 minutes on 2 cores);
``--no-ray`` runs the two thread pool rows only.
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def campaign(out: Path, seeds: str, stains: str, skill: Path, jobs: int, ray: bool, network: bool,
             env: dict) -> tuple[float, float, list[dict]]:
    """(wall [s], CPU of the campaign and every child it waited for [s], its cells)."""
    argv = [sys.executable, "-m", "runtime.cli", "campaign", "--seeds", seeds, "--stains", stains, "--boards",
            "wall", "--jobs", str(jobs), "--skill", str(skill), "--out", str(out)] + (["--ray"] if ray else []) \
        + ([] if network else ["--no-network"])
    cpu0 = os.times()
    t0 = time.monotonic()
    r = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, env=env)
    wall = time.monotonic() - t0
    cpu1 = os.times()
    if r.returncode != 0:
        raise SystemExit(f"campaign failed: {r.stderr[-2000:]}")
    cpu = (cpu1.children_user - cpu0.children_user) + (cpu1.children_system - cpu0.children_system)
    return wall, cpu, json.loads((out / "campaign.json").read_text())["cells"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--stains", default="1-3")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--no-ray", action="store_true", help="the thread pool rows only (no Ray cluster)")
    a = ap.parse_args()
    env = {**os.environ, "MPLBACKEND": "Agg", "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(16)}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        learn = subprocess.run([sys.executable, "-m", "runtime.cli", "demo", "--stains", "3", "--seed", "0", "--out",
                                str(tmp / "learn")], cwd=REPO, capture_output=True, text=True, env=env)
        if learn.returncode != 0:
            raise SystemExit(f"learning failed: {learn.stderr[-1000:]}")
        skill = tmp / "learn" / "skill.json"
        runs = [("Zenoh cells, thread pool --jobs 2 (baseline)", 2, False, True),
                ("network-free cells, thread pool --jobs 2", 2, False, False),
                ("network-free cells, Ray 1 worker", 1, True, False),
                ("network-free cells, Ray 2 workers", 2, True, False)]
        runs = [r for r in runs if not (a.no_ray and r[2])]
        rows = []
        base_cells = None
        for i, (name, jobs, ray, network) in enumerate(runs):
            wall, cpu, cells = campaign(tmp / f"campaign-{i}", a.seeds, a.stains, skill, jobs, ray, network, env)
            same = gap = None
            if base_cells is None:
                base_cells = {c["name"]: c for c in cells}
            else:
                same = all(c["outcome"] == base_cells[c["name"]]["outcome"]
                           and abs(c["dirt_removed"] - base_cells[c["name"]]["dirt_removed"]) < 0.005 for c in cells)
                gap = max(abs(c["dirt_removed"] - base_cells[c["name"]]["dirt_removed"]) for c in cells)
            outcomes = sorted({c["outcome"] for c in cells})
            rows.append(dict(name=name, cells=len(cells), wall_s=wall, per_hour=3600.0 * len(cells) / wall, same=same,
                             max_dirt_gap=gap, cpu_per_cell_s=None if ray else cpu / len(cells), outcomes=outcomes))
    rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip()
    base = rows[0]["per_hour"]
    print(f"cells of seeds {a.seeds}, stains {a.stains} (wall board, lock-step), {os.cpu_count()} CPUs, at {rev}\n")
    print("| campaign | cells | outcomes | wall [s] | CPU per cell [s] | cells per hour | vs baseline | same outcome "
          "and dirt (0.5 pt) as the baseline | largest dirt difference [pt] |")
    print("|---|---:|---|---:|---:|---:|---:|---|---:|")
    for r in rows:
        same = "-" if r["same"] is None else ("yes" if r["same"] else "NO")
        gap = "-" if r["max_dirt_gap"] is None else f"{100 * r['max_dirt_gap']:.2f}"
        print(f"| {r['name']} | {r['cells']} | {', '.join(r['outcomes'])} | {r['wall_s']:.0f} | "
              f"{'-' if r['cpu_per_cell_s'] is None else format(r['cpu_per_cell_s'], '.0f')} | "
              f"{r['per_hour']:.0f} | {r['per_hour'] / base:.2f}x | {same} | {gap} |")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
