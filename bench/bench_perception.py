"""Perception benchmark: processing time per 640x480 frame on one core, and kappa latency in the closed loop.

1. Frames rendered by ``lamps sim`` (lock-step, wall board, 4 seeded stains,
   the arm parked and the arm over the board) are processed by
   :class:`perception.pipeline.Perception` with OpenCV on one thread; per
   stage and total; the arm-over-board frames again with the eraser masked
   out (the self-filter, from the joint states of the same run). Baseline in the same run: the same stain
   pixels clustered with scikit-learn's DBSCAN (``min_samples = 1``, same link distance), the
   paper's pixel clustering done directly.
2. The closed loop over real Zenoh (``lamps sim`` with its camera, the
   controller taking stains from perception, perception on the sim's
   frames): for each stain, when the truth fell below the kappa level, when
   the stain was back in view, and when perception published kappa (sim
   time), plus the wall-clock age of each published stains message.

3. Against a named baseline revision (``--baseline REV``, checked out into
   a temporary git worktree), the same frames in one run: each tree's
   perception package in its own Python process on one OpenCV thread,
   trees alternating for ``--rounds``; per frame set the frame-to-message
   latency (wall clock from the frame message's decoding to the stains
   message, p50 and p99) and the frames/s on one core (1000 / the p50 of
   the thread's CPU time per frame [ms]).

Run: ``.venv/bin/python bench/bench_perception.py [--baseline REV] [--json OUT]`` (about 3 minutes); prints
markdown tables.
"""

from __future__ import annotations

import json
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from sklearn.cluster import DBSCAN  # noqa: E402

from arm.robot_model import RobotModel  # noqa: E402
from interfaces.messages import CameraFrame  # noqa: E402
from perception.cluster import cluster_pixels  # noqa: E402
from perception.evaluate import kappa_timings  # noqa: E402
from perception.frames import frame_from_message  # noqa: E402
from perception.params import PerceptionParams  # noqa: E402
from perception.pipeline import Perception  # noqa: E402
from perception.self_filter import tool_corners  # noqa: E402
from tests.zenoh_helpers import SimProcess, run_lockstep, wait_for  # noqa: E402  (the real sim, started as in tests)

PARKED_Q = [2.6, 0.3, 0.0, -1.2, 0.0, 0.8, 0.0]
MODEL = RobotModel()


def render(tmp: Path, model: RobotModel, cfg: dict, steps: int, states: list | None = None) -> list[CameraFrame]:
    """The sim's frames over ``steps`` lock-step ticks (the arm held by gravity compensation); ``states``: also
    collect its joint states ``(robot_time_ns, q)`` there."""
    with SimProcess(tmp, {"mode": "lockstep", "camera": {"rate_hz": 10.0}, **cfg}) as sim:
        inbox = sim.node.inbox(sim.keys.camera_frame("board"), CameraFrame, maxlen=10_000)

        def law(s):
            if states is not None:
                states.append((s.robot_time_ns, np.array(s.q_rad)))
            return model.gravity(np.array(s.q_rad)) - 5.0 * np.array(s.dq_rad_s)

        run_lockstep(sim, steps, law)
        wait_for(lambda: inbox.received >= steps // 100 - 1, 30.0, "frames")
        out = []
        while (f := inbox.get(0.0)) is not None:
            out.append(f)
    return out


def tool_at(states: list, robot_time_ns: int) -> np.ndarray:
    """The eraser's box (8, 3) [m] at the joint state nearest ``robot_time_ns`` (as the service's ToolTrack)."""
    t = np.array([s[0] for s in states])
    q = states[int(np.argmin(np.abs(t - robot_time_ns)))][1]
    return tool_corners(*MODEL.tcp_pose(q))


def bench_frames(frames: list[CameraFrame], repeat: int = 3, states: list | None = None) -> dict:
    """Per-frame processing time; ``states`` (joint states of the run): with the eraser masked out of each frame
    (the self-filter; the pose lookup and forward kinematics counted in the mask stage)."""
    cv2.setNumThreads(1)
    stages: dict[str, list[float]] = {}
    totals, dbscan_ms, ours_ms, found = [], [], [], []
    for _ in range(repeat):
        p = Perception(PerceptionParams())
        for msg in frames:
            f = frame_from_message(msg)
            t0 = time.perf_counter()
            tool = tool_at(states, f.robot_time_ns) if states is not None else None
            t_tool = time.perf_counter()
            r = p.process(f, tool)
            if states is not None:
                r.timing_ms["mask"] = r.timing_ms.get("mask", 0.0) + (t_tool - t0) * 1e3
            totals.append((time.perf_counter() - t0) * 1e3)
            for k, v in r.timing_ms.items():
                stages.setdefault(k, []).append(v)
            if r.stains is not None:
                found.append(len(r.stains.stains))
            if r.ink is not None:
                mask = r.ink.stain
                link = p.tracker.link_px
                t0 = time.perf_counter()
                cluster_pixels(mask, link)
                ours_ms.append((time.perf_counter() - t0) * 1e3)
                pts = np.argwhere(mask)
                t0 = time.perf_counter()
                if len(pts):
                    DBSCAN(eps=link, min_samples=1).fit_predict(pts)
                dbscan_ms.append((time.perf_counter() - t0) * 1e3)
    tot = np.array(totals[len(frames) // 4:])  # after the first frames (board measured, buffers warm)
    return {
        "frames": len(totals), "p50_ms": float(np.percentile(tot, 50)), "p99_ms": float(np.percentile(tot, 99)),
        "fps_one_core_p50": 1000.0 / float(np.percentile(tot, 50)),
        "stages_p50_ms": {k: float(np.percentile(v, 50)) for k, v in stages.items()},
        "clustering_p50_ms": float(np.percentile(ours_ms, 50)), "dbscan_p50_ms": float(np.percentile(dbscan_ms, 50)),
        "dbscan_over_ours": float(np.percentile(dbscan_ms, 50) / max(np.percentile(ours_ms, 50), 1e-6)),
        "stains_found_median": float(np.median(found)) if found else 0.0,
    }


# What each tree runs on the pickled frame sets: per set, (wall ms, CPU ms) per frame after the first quarter.
WORKER = r"""
import pickle, sys, time
import numpy as np, cv2
cv2.setNumThreads(1)
sys.path.insert(0, sys.argv[1])
from arm.robot_model import RobotModel
from perception.frames import frame_from_message
from perception.params import PerceptionParams
from perception.pipeline import Perception
from perception.self_filter import tool_corners
sets = pickle.load(open(sys.argv[2], "rb"))
model = RobotModel()
out = {}
for name, (frames, states) in sets.items():
    t_states = np.array([s[0] for s in states]) if states else None
    p = Perception(PerceptionParams())
    wall, cpu = [], []
    for msg in frames:
        t0, c0 = time.perf_counter(), time.thread_time()
        f = frame_from_message(msg)
        tool = None
        if states:
            tool = tool_corners(*model.tcp_pose(states[int(np.argmin(np.abs(t_states - f.robot_time_ns)))][1]))
        p.process(f, tool)
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.thread_time() - c0) * 1e3)
    out[name] = dict(wall=wall[len(frames) // 4:], cpu=cpu[len(frames) // 4:])
pickle.dump(out, open(sys.argv[3], "wb"))
"""


def against_baseline(sets: dict, baseline: str, rounds: int) -> dict:
    """Per frame set ``name -> (frames, states or None)``: latency p50/p99 and frames/s of the baseline revision
    and of this tree, and the median ratio of their CPU times over the rounds (trees alternating)."""
    import tempfile as _tempfile

    out: dict = {}
    with _tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "baseline"
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(base), baseline], check=True,
                       capture_output=True)
        try:
            (tmp / "sets.pkl").write_bytes(pickle.dumps(sets))
            runs: dict = {"baseline": {k: dict(wall=[], cpu=[]) for k in sets},
                          "this": {k: dict(wall=[], cpu=[]) for k in sets}}
            ratios: dict = {k: [] for k in sets}
            for _ in range(rounds):
                got = {}
                for which, tree in (("baseline", base), ("this", REPO)):
                    subprocess.run([sys.executable, "-c", WORKER, str(tree), str(tmp / "sets.pkl"),
                                    str(tmp / "out.pkl")], check=True, cwd=tree)
                    got[which] = pickle.loads((tmp / "out.pkl").read_bytes())
                    for k in sets:
                        runs[which][k]["wall"] += got[which][k]["wall"]
                        runs[which][k]["cpu"] += got[which][k]["cpu"]
                for k in sets:
                    ratios[k].append(np.median(got["this"][k]["cpu"]) / np.median(got["baseline"][k]["cpu"]))
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(base)], check=False)
    for k in sets:
        out[k] = {which: {"latency_p50_ms": float(np.percentile(runs[which][k]["wall"], 50)),
                          "latency_p99_ms": float(np.percentile(runs[which][k]["wall"], 99)),
                          "fps_one_core": 1e3 / float(np.median(runs[which][k]["cpu"]))} for which in runs}
        out[k]["cpu_ratio_median"] = float(np.median(ratios[k]))
        out[k]["cpu_ratio_range"] = [float(np.min(ratios[k])), float(np.max(ratios[k]))]
    return out


def grid_stains(n_x: int, n_y: int, board_m=(0.8, 0.6), margin_m: float = 0.13, size_m: float = 0.045) -> list[dict]:
    """``n_x * n_y`` stains on a grid over the wall board (board frame), as ``[sim.dirt] stain`` tables."""
    xs = np.linspace(margin_m, board_m[0] - margin_m, n_x)
    ys = np.linspace(margin_m, board_m[1] - margin_m, n_y)
    return [{"centre_m": [float(x), float(y)], "size_m": size_m, "aspect": 1.3, "angle_deg": float(30 * (i % 4))}
            for i, (x, y) in enumerate((x, y) for y in ys for x in xs)]


def bench_closed_loop(tmp: Path) -> dict:
    from lampskit.learn.learn import bundled_skill
    from tests.test_perception_service import run_closed_loop

    run = run_closed_loop(tmp, bundled_skill(), timeout_s=600.0)
    truths, sent, status = run.truths, run.sent, run.perception_status
    out = [{"stain": k.truth_index, "truth_below_s": k.truth_below_s, "in_view_s": k.in_view_s,
            "kappa_s": k.kappa_s, "latency_from_truth_s": k.kappa_s - k.truth_below_s,
            "latency_from_view_s": k.kappa_s - k.in_view_s}
           for k in kappa_timings([m for _, m in sent], truths, run.kappa)]
    rates = np.diff([t for t, _ in sent])
    return {"stains": out, "final_remaining": truths[-1].remaining, "sim_time_s": truths[-1].robot_time_ns * 1e-9,
            "wall_s": run.wall_s, "publish_interval_p50_ms": float(np.median(rates) * 1e3),
            "publish_interval_max_ms": float(rates.max() * 1e3),
            "process_p50_us": status.counters.get("process_p50_us"), "frames": status.counters.get("frames_processed")}


def markdown(result: dict) -> str:
    """The README's tables from the result."""
    out = ["| per 640x480 frame, one core | p50 [ms] | p99 [ms] | frames/s (p50) | stages p50 [ms]: board / rectify / "
           "classify / track |", "|---|---:|---:|---:|---|"]
    for key, label in (("frames_arm_parked", "arm parked away from the board"),
                       ("frames_arm_over_board", "arm over the board"),
                       ("frames_arm_over_board_masked", "arm over the board, the eraser masked (self-filter)")):
        r = result[key]
        st = r["stages_p50_ms"]
        mask = f" (+ mask {st['mask']:.2f})" if "mask" in st else ""
        out.append(f"| {label} | {r['p50_ms']:.1f} | {r['p99_ms']:.1f} | {r['fps_one_core_p50']:.1f} | "
                   f"{st['board']:.1f} / {st['rectify']:.1f}{mask} / {st['classify']:.1f} / {st['track']:.1f} |")
    out += ["", "| scale: per frame, arm parked, stains on a grid | stains found (median) | p50 [ms] | p99 [ms] | "
            "classify / track p50 [ms] |", "|---|---:|---:|---:|---|"]
    for key, label in (("frames_3_stains", "3 stains"), ("frames_20_stains", "20 stains")):
        r = result[key]
        st = r["stages_p50_ms"]
        out.append(f"| {label} | {r['stains_found_median']:.0f} | {r['p50_ms']:.1f} | {r['p99_ms']:.1f} | "
                   f"{st['classify']:.1f} / {st['track']:.1f} |")
    r = result["frames_arm_parked"]
    out += ["", "| clustering of the stain pixels | p50 [ms] | baseline, same frames |", "|---|---:|---|",
            f"| ours (dilation + connected components) | {r['clustering_p50_ms']:.2f} | scikit-learn DBSCAN "
            f"(min_samples 1, same link): {r['dbscan_p50_ms']:.1f} ms, {r['dbscan_over_ours']:.0f}x slower |"]
    if "baseline" in result:
        b, n = result["baseline_rev"], result["rev"]
        out += ["", f"| same frames, one core | {b} latency p50 / p99 [ms] | {b} frames/s | {n} latency p50 / p99 "
                f"[ms] | {n} frames/s | CPU time ratio (rounds' median, range) |", "|---|---:|---:|---:|---:|---|"]
        for k, r in result["baseline"].items():
            lo, hi = r["cpu_ratio_range"]
            out.append(f"| {k} | {r['baseline']['latency_p50_ms']:.1f} / {r['baseline']['latency_p99_ms']:.1f} | "
                       f"{r['baseline']['fps_one_core']:.0f} | {r['this']['latency_p50_ms']:.1f} / "
                       f"{r['this']['latency_p99_ms']:.1f} | {r['this']['fps_one_core']:.0f} | "
                       f"{r['cpu_ratio_median']:.2f}x ({lo:.2f}-{hi:.2f}) |")
    cl = result["closed_loop"]
    out += ["", "| closed loop (sim time), per stain | truth <= 3 % | back in view | kappa published | "
            "kappa after truth | kappa after in view |", "|---|---:|---:|---:|---:|---:|"]
    for k in cl["stains"]:
        out.append(f"| stain {k['stain']} | {k['truth_below_s']:.1f} s | {k['in_view_s']:.1f} s | {k['kappa_s']:.1f} s "
                   f"| {k['latency_from_truth_s']:.1f} s | {k['latency_from_view_s']:.1f} s |")
    out.append(f"\nclosed loop: {cl['sim_time_s']:.1f} s sim time ({cl['wall_s']:.0f} s wall), stains published every "
               f"{cl['publish_interval_p50_ms']:.0f} ms (p50, max {cl['publish_interval_max_ms']:.0f} ms)")
    return "\n".join(out)


def main() -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="accepted for lamps bench; the run is the same")
    ap.add_argument("--json", type=Path, help="also write the figures here")
    ap.add_argument("--baseline", help="git revision to compare with on the same frames (e.g. e95f293)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of baseline then this tree")
    a = ap.parse_args()
    model = RobotModel()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        parked = render(tmp, model, {"seed": 0, "start_q_rad": PARKED_Q, "dirt": {"stains": 4}}, 3000)
        states: list = []
        arm = render(tmp, model, {"seed": 0, "dirt": {"stains": 4}}, 3000, states)
        three = render(tmp, model, {"seed": 0, "start_q_rad": PARKED_Q, "dirt": {"stain": grid_stains(3, 1)}}, 2000)
        twenty = render(tmp, model, {"seed": 0, "start_q_rad": PARKED_Q, "dirt": {"stain": grid_stains(5, 4)}}, 2000)
        result = {"frames_arm_parked": bench_frames(parked), "frames_arm_over_board": bench_frames(arm),
                  "frames_arm_over_board_masked": bench_frames(arm, states=states),
                  "frames_3_stains": bench_frames(three), "frames_20_stains": bench_frames(twenty),
                  "closed_loop": bench_closed_loop(tmp)}
        if a.baseline:
            result["baseline_rev"] = a.baseline
            result["rev"] = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                                           capture_output=True, text=True).stdout.strip()
            result["baseline"] = against_baseline({"arm parked": (parked, None), "arm over the board": (arm, None),
                                                   "arm over the board, the eraser masked": (arm, states),
                                                   "20 stains": (twenty, None)}, a.baseline, a.rounds)
    print(markdown(result))
    if a.json:
        a.json.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
