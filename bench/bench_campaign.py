"""Campaign throughput: cells per hour on this machine, locally and as Ray tasks with 1 and 2 workers, one run.

The same cells each time (``--seeds``, one stain, the wall board, fixed
wiping, the bundled demo learned once): ``lamps campaign --jobs 2`` (the
local thread pool, the baseline), then ``--ray --jobs 1`` and ``--ray
--jobs 2`` (a local Ray cluster started for the campaign with that many
CPUs; Ray's token authentication on). Prints wall time, cells per hour,
the ratio to the baseline and whether every cell gave the same outcome
and dirt removed (within 0.5 points) as the baseline's.

Run: ``.venv/bin/python bench/bench_campaign.py [--seeds 0-3]`` (about 8 minutes on 2 cores).
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


def campaign(out: Path, seeds: str, skill: Path, jobs: int, ray: bool, env: dict) -> tuple[float, list[dict]]:
    argv = [sys.executable, "-m", "interfaces.cli", "campaign", "--seeds", seeds, "--stains", "1", "--boards", "wall",
            "--jobs", str(jobs), "--skill", str(skill), "--out", str(out)] + (["--ray"] if ray else [])
    t0 = time.monotonic()
    r = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, env=env)
    wall = time.monotonic() - t0
    if r.returncode != 0:
        raise SystemExit(f"campaign failed: {r.stderr[-2000:]}")
    return wall, json.loads((out / "campaign.json").read_text())["cells"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-3")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    env = {**os.environ, "MPLBACKEND": "Agg", "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(16)}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        learn = subprocess.run([sys.executable, "-m", "interfaces.cli", "demo", "--stains", "3", "--seed", "0", "--out",
                                str(tmp / "learn")], cwd=REPO, capture_output=True, text=True, env=env)
        if learn.returncode != 0:
            raise SystemExit(f"learning failed: {learn.stderr[-1000:]}")
        skill = tmp / "learn" / "skill.json"
        runs = [("local thread pool, --jobs 2 (baseline)", 2, False), ("Ray, 1 worker", 1, True),
                ("Ray, 2 workers", 2, True)]
        rows = []
        base_cells = None
        for i, (name, jobs, ray) in enumerate(runs):
            wall, cells = campaign(tmp / f"campaign-{i}", a.seeds, skill, jobs, ray, env)
            same = None
            if base_cells is None:
                base_cells = {c["name"]: c for c in cells}
            else:
                same = all(c["outcome"] == base_cells[c["name"]]["outcome"]
                           and abs(c["dirt_removed"] - base_cells[c["name"]]["dirt_removed"]) < 0.005 for c in cells)
            rows.append(dict(name=name, cells=len(cells), wall_s=wall, per_hour=3600.0 * len(cells) / wall, same=same))
    rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip()
    base = rows[0]["per_hour"]
    print(f"cells of seeds {a.seeds} (one stain, wall board, lock-step), {os.cpu_count()} CPUs, at {rev}\n")
    print("| campaign | cells | wall [s] | cells per hour | vs baseline | same outcome and dirt as the baseline |")
    print("|---|---:|---:|---:|---:|---|")
    for r in rows:
        same = "-" if r["same"] is None else ("yes" if r["same"] else "NO")
        print(f"| {r['name']} | {r['cells']} | {r['wall_s']:.0f} | {r['per_hour']:.0f} | {r['per_hour'] / base:.2f}x | "
              f"{same} |")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
