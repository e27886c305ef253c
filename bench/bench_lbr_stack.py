"""The cell through the simulated lbr stack against the plain sim: same seeds, same run, lock-step and real time.

    python bench/bench_lbr_stack.py [--seeds 1,2,3] [--modes lockstep,realtime] [--out DIR]

Each seed runs ``lamps up`` twice per mode: ``--robot sim`` (the PyBullet arm
served directly) and ``--robot lbr-sim`` (the same arm behind the stack's
messages, behaving as its code does: the app's 200 Nm/rad joint spring, the
stack's PID, its 10 Hz torque filter, the controller manager at 1 kHz, the
last message re-applied; driven by the real-robot adapter). Printed: per
cell the dirt removed, robot time, tracking RMS, the wiping force (mean,
std, max), the largest joint spring torque the robot applied; then the
medians per robot side and mode and their ratio (lbr-sim / sim). The
figures land in ``DIR/bench_lbr_stack.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ROBOTS = ("sim", "lbr-sim")


def run_cell(seed: int, robot: str, mode: str, out: Path) -> dict:
    """One ``lamps up``; the figures of its report."""
    run_dir = out / f"{mode}-{robot}-{seed}"
    t0 = time.monotonic()
    up = "import sys; from launch.cli import up_main; sys.exit(up_main(sys.argv[1:]))"
    r = subprocess.run([sys.executable, "-c", up, "--seed", str(seed), "--robot", robot, "--mode", mode, "--out",
                        str(run_dir), "-q"], cwd=REPO, capture_output=True, text=True, timeout=900)
    wall = time.monotonic() - t0
    report = run_dir / "report.json"
    if not report.exists():
        return {"seed": seed, "robot": robot, "mode": mode, "error": (r.stderr or r.stdout)[-300:], "wall_s": wall}
    rep = json.loads(report.read_text())
    sim_counters = rep.get("counters", {}).get("sim", {})
    return {"seed": seed, "robot": robot, "mode": mode, "outcome": rep.get("outcome"),
            "removed": rep.get("dirt_removed_fraction"), "robot_time_s": rep.get("sim_time_s"),
            "tracking_rms_mm": 1e3 * rep["tracking_rms_m"] if rep.get("tracking_rms_m") is not None else None,
            "force_mean_n": rep.get("normal_force_mean_n"), "force_std_n": rep.get("normal_force_std_n"),
            "force_max_n": rep.get("max_contact_force_n"),
            "spring_max_nm": sim_counters.get("spring_max_mnm", 0) / 1e3 if robot == "lbr-sim" else None,
            "wall_s": round(wall, 1)}


def _median(rows: list[dict], key: str) -> float | None:
    vals = [r[key] for r in rows if r.get(key) is not None]
    return statistics.median(vals) if vals else None


def _fmt(v, spec: str = ".2f") -> str:
    return "-" if v is None else format(v, spec)


def table(rows: list[dict], modes: list[str]) -> str:
    lines = ["| mode | robot side | seed | outcome | removed | robot time [s] | tracking RMS [mm] | force [N] | "
             "max force [N] | joint spring max [Nm] |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['mode']} | {r['robot']} | {r['seed']} | error: {r['error'][:80]!r} |||||||")
            continue
        lines.append(f"| {r['mode']} | {r['robot']} | {r['seed']} | {r['outcome']} | "
                     f"{_fmt(100 * r['removed'], '.1f')} % | "
                     f"{_fmt(r['robot_time_s'], '.1f')} | {_fmt(r['tracking_rms_mm'])} | "
                     f"{_fmt(r['force_mean_n'], '.1f')} +- {_fmt(r['force_std_n'], '.1f')} | "
                     f"{_fmt(r['force_max_n'], '.1f')} | {_fmt(r['spring_max_nm'])} |")
    lines += ["", "| mode | medians: sim | lbr-sim | ratio lbr-sim / sim |", "|---|---|---|---|"]
    for mode in modes:
        for key, label in (("tracking_rms_mm", "tracking RMS [mm]"), ("force_std_n", "force std [N]"),
                           ("force_max_n", "max force [N]"), ("robot_time_s", "robot time [s]")):
            a = _median([r for r in rows if r["mode"] == mode and r["robot"] == "sim"], key)
            b = _median([r for r in rows if r["mode"] == mode and r["robot"] == "lbr-sim"], key)
            ratio = b / a if a and b is not None else None
            lines.append(f"| {mode} | {label}: {_fmt(a)} | {_fmt(b)} | {_fmt(ratio)} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1,2,3", help="comma-separated seeds (default 1,2,3)")
    ap.add_argument("--modes", default="lockstep,realtime", help="lockstep, realtime or both (default both)")
    ap.add_argument("--out", default="bench-results/lbr-stack", help="where the runs and the table go")
    a = ap.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
    modes = [m for m in a.modes.split(",") if m]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for mode in modes:
        for seed in seeds:
            for robot in ROBOTS:
                row = run_cell(seed, robot, mode, out)
                print(json.dumps(row), flush=True)
                rows.append(row)
    md = table(rows, modes)
    (out / "bench_lbr_stack.json").write_text(json.dumps(rows, indent=2) + "\n")
    (out / "bench_lbr_stack.md").write_text(md + "\n")
    print(md)
    return 1 if any("error" in r for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
