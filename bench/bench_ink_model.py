"""Perception against a named baseline revision, same frames, same run: frames/s, latency and stain figures.

Frames:

- ``sim``: the simulator's camera at 640x480 (wall board, the seeded stains
  of seeds 1..N, the arm parked), rendered in this process with PyBullet's
  TinyRenderer and the sim's dirt compositing (what ``lamps sim`` sends);
  the truth is the dirt grid (stain where dirt >= stain_level).
- ``photo``: the three real photographs (tests/fixtures/whiteboards) as a
  1280x720 camera sends them (scaled to 720 rows, the sides filled with
  their own mirrored pixels) and at their 1160x870, with their board.toml
  (the real-board profile: six inks, the local white); the truth is
  stains.toml's hand-made masks.

Each image is watched as a camera sends it: :data:`WATCH` frames at 10 Hz,
each with fresh sensor noise (seeded, the same pixels for both trees), by a
fresh :class:`perception.pipeline.Perception`; the last :data:`TIMED` are
timed from the frame's arrival to the stains message (the frame-to-message
latency, wall clock) and by the CPU time of the thread that ran them
(frames/s on one core: 1000 / its p50 in ms, what a loaded machine does
not change much). Each code tree (this
checkout, and ``--baseline REV`` checked out into a temporary git
worktree) runs in its own Python process on one OpenCV thread,
``--repeat`` times, trees alternating (A B A B ...) so a busy machine slows
both alike; per frame set the p50 and p99 of each tree over all rounds,
and the median (and range) of the rounds' ratios, are printed. The stain
figures (IoU of the stain areas against the truth, the false stain area
over the clean board) are computed here from each tree's classification of
the image without added noise, with :mod:`perception.ink_areas`, and the
largest change between the trees is printed.

Run: ``.venv/bin/python bench/bench_ink_model.py --baseline REV [--seeds 6] [--repeat 2] [--rounds 5]``
(about 5 minutes).
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from perception.ink_areas import compare, ink_areas  # noqa: E402
from perception.params import PerceptionParams  # noqa: E402
from perception.photo_score import OUTLINE_TOLERANCE_M, truth_masks  # noqa: E402
from perception.rectify import BoardGrid  # noqa: E402

PHOTOS = REPO / "tests" / "fixtures" / "whiteboards"
PHOTO_INKS = ("red", "blue", "green", "purple", "brown")

#: Frames each image is watched for: the first ones find the board and confirm the stains, the rest are timed.
WATCH, TIMED = 12, 8
#: The sensor noise of each watched frame (grey levels, Gaussian), as a camera sends one scene again and again.
NOISE_SIGMA = 2.0

# What each tree runs: per image a fresh Perception watches it for WATCH frames (fresh noise each, 10 Hz), the last
# TIMED frames timed from the frame's arrival to the stains message (the frame-to-message latency); the figures
# come from one more frame, the image without added noise. Out: per set the latencies and per image (stain mask,
# ink labels, names, d, looked_at, visible, board size).
WORKER = r"""
import pickle, sys, time
import cv2, numpy as np
cv2.setNumThreads(1)
sys.path.insert(0, sys.argv[1])
from perception.frames import Frame
from perception.params import PerceptionParams
from perception.pipeline import Perception
sets = pickle.load(open(sys.argv[2], "rb"))
out = {}
for name, s in sets.items():
    params = PerceptionParams.from_table(s["config"])
    times, cpu, last = [], [], []
    for rep in range(int(sys.argv[4])):
        for (rgb, K, T), noisy in zip(s["frames"], s["noisy"]):
            p = Perception(params)
            for i, img in enumerate(noisy):
                t0, c0 = time.perf_counter(), time.thread_time()
                r = p.process(Frame(img, K, T, 0.1 * i, i))
                dt, dc = time.perf_counter() - t0, time.thread_time() - c0
                if i >= len(noisy) - int(sys.argv[5]):
                    times.append(dt * 1e3)
                    cpu.append(dc * 1e3)
            if rep == 0:
                r = p.process(Frame(rgb, K, T, 0.1 * len(noisy), len(noisy)))
                ink = r.ink
                labels = getattr(ink, "ink", None)
                last.append(dict(stain=ink.stain, ink=labels, names=getattr(ink, "names", ("ink",)),
                                 d=ink.d, looked_at=ink.looked_at, visible=ink.visible, size_m=r.board.size_m,
                                 stains=len(r.stains.stains) if r.stains is not None else 0))
    out[name] = dict(ms=times, cpu_ms=cpu, frames=last)
pickle.dump(out, open(sys.argv[3], "wb"))
"""


def with_noise(frames: list, seed: int = 0) -> list:
    """Per frame (rgb, K, T), :data:`WATCH` copies of its image with fresh sensor noise (seeded: both trees see
    the same pixels)."""
    rng = np.random.default_rng(seed)
    out = []
    for rgb, _, _ in frames:
        out.append([np.clip(rgb + rng.normal(0.0, NOISE_SIGMA, rgb.shape), 0, 255).astype(np.uint8)
                    for _ in range(WATCH)])
    return out


def sim_frames(seeds: int) -> tuple[list, list, dict]:
    """``(frames [(rgb, K, T_camera_to_world)], truths [(dirt (ny, nx), cell_m, size_m)], config)`` of seeds
    1..``seeds`` at 640x480, the arm parked."""
    import pybullet as pb

    from perception.frames import camera_matrix
    from sim.camera import (
        board_cell_index,
        board_texture,
        camera_pose,
        composite_dirt,
        intrinsics_of,
        light_towards,
        marker_layer,
        projection_matrix,
        view_matrix,
    )
    from sim.core import SimCore
    from sim.params import SimParams
    from sim.world import build_world

    frames, truths = [], []
    for seed in range(1, seeds + 1):
        params = SimParams.from_table({"seed": seed, "camera": {"width": 640, "height": 480}})
        core = SimCore(params)
        client = pb.connect(pb.DIRECT)
        try:
            world = build_world(client, core.board, params.contact, np.array([2.6, 0.3, 0.0, -1.2, 0.0, 0.8, 0.0]),
                                visual=True)
            # the texture carries the markers only; the dirt is composited per frame, as the sim's renderer does
            tex = board_texture(np.zeros_like(core.dirt.dirt), params.dirt.cell_m, marker_layer(core.board.size_m),
                                core.board.size_m)
            with tempfile.TemporaryDirectory() as tmp:
                path = str(Path(tmp) / "board.png")
                cv2.imwrite(path, tex[..., ::-1])
                tex_id = pb.loadTexture(path, physicsClientId=client)
            pb.changeVisualShape(world.board, -1, textureUniqueId=tex_id, physicsClientId=client)
            k = intrinsics_of(params.camera)
            T_cam = camera_pose(params.camera, core.board)
            out = pb.getCameraImage(k.width, k.height, view_matrix(T_cam), projection_matrix(k),
                                    renderer=pb.ER_TINY_RENDERER, shadow=1,
                                    lightDirection=light_towards(params.camera, core.board), physicsClientId=client)
            rgb = np.asarray(out[2], np.uint8).reshape(k.height, k.width, 4)[..., :3].copy()
            cells = board_cell_index(k, T_cam, core.board, params.dirt.cell_m, core.dirt.dirt.shape)
            composite_dirt(rgb, np.asarray(out[4]).reshape(-1) == world.board, cells, core.dirt.dirt)
            frames.append((rgb, camera_matrix(k), T_cam))
            truths.append((core.dirt.dirt.copy(), params.dirt.cell_m, tuple(core.board.size_m)))
        finally:
            pb.disconnect(client)
            core.close()
    return frames, truths, {}


def photo_frames(width: int, height: int | None = None) -> tuple[list, list, dict]:
    """The three photographs at ``width`` (aspect kept), their hand-made masks and board.toml's config; with
    ``height`` (a 16:9 camera, 1280x720) each photograph is scaled to that height and its sides filled with its
    own mirrored pixels up to ``width`` (the board is where a 4:3 image of that height puts it; the marker
    search, the colour conversion and any undistortion see every pixel of the wider frame)."""
    from perception.sources import camera_model

    config = tomllib.loads((PHOTOS / "board.toml").read_text())["perception"]
    labels = tomllib.loads((PHOTOS / "stains.toml").read_text())
    params = PerceptionParams.from_table(config)
    frames, truths = [], []
    for name in ("straight", "sideangle", "highangle"):
        bgr = cv2.imread(str(PHOTOS / f"{name}.jpg"))
        if height is None:
            h = int(round(bgr.shape[0] * width / bgr.shape[1]))
            bgr = cv2.resize(bgr, (width, h), interpolation=cv2.INTER_AREA)
            K, T = camera_model(params.model, width, h)
        else:
            w = int(round(bgr.shape[1] * height / bgr.shape[0]))
            bgr = cv2.resize(bgr, (w, height), interpolation=cv2.INTER_AREA)
            side = (width - w) // 2
            bgr = cv2.copyMakeBorder(bgr, 0, 0, side, width - w - side, cv2.BORDER_REFLECT_101)
            K, T = camera_model(params.model, w, height)
            K = K.copy()
            K[0, 2] += side
        frames.append((cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), K, T))
        truths.append(labels[name]["stains"])
    return frames, truths, config


def sim_truth(dirt: np.ndarray, cell_m: float, grid: BoardGrid, level: float) -> np.ndarray:
    """(rows, cols) bool: grid pixels whose dirt cell holds at least ``level``."""
    rows, cols = grid.shape
    xy = grid.xy_of(np.repeat(np.arange(rows), cols), np.tile(np.arange(cols), rows))
    ix = np.clip((xy[:, 0] / cell_m).astype(int), 0, dirt.shape[1] - 1)
    iy = np.clip((xy[:, 1] / cell_m).astype(int), 0, dirt.shape[0] - 1)
    return (dirt[iy, ix] >= level).reshape(rows, cols)


def figures(kind: str, result: dict, truths: list, config: dict) -> dict:
    """Mean IoU per ink, worst IoU, and the largest false area over the frames of one set."""
    params = PerceptionParams.from_table(config)
    ious: dict[str, list[float]] = {}
    false, seen, per_frame = [], [], []
    for f, truth in zip(result["frames"], truths):
        grid = BoardGrid(tuple(f["size_m"]), params.board.resolution_m)

        class _Ink:  # what ink_areas reads, from the worker's arrays (either tree)
            stain, d, names = f["stain"], f["d"], tuple(f["names"])
            ink = f["ink"]

        if kind == "sim":
            want = {f["names"][0]: sim_truth(truth[0], truth[1], grid, params.ink.stain_level)}
        else:
            want = truth_masks(grid, truth)
        areas = ink_areas(_Ink, params.board.resolution_m, params.stains.link_m, params.stains.min_area_m2)
        tol = int(round(OUTLINE_TOLERANCE_M / params.board.resolution_m)) if kind == "photo" else 0
        scores, fa = compare(areas, want, f["stain"], f["visible"], f["looked_at"], tol)
        for s in scores:
            if s.seen >= 0.5:  # a drawing mostly hidden (glare) is not scored; its share is reported
                ious.setdefault(s.ink, []).append(s.iou)
            seen.append(s.seen)
        false.append(fa)
        occluded = float((f["looked_at"] & ~f["visible"]).sum()) / max(int(f["looked_at"].sum()), 1)
        per_frame.append(dict(scores=[(s.ink, s.iou, s.seen) for s in scores], false=fa, occluded=occluded))
    return {"iou": {k: float(np.mean(v)) for k, v in ious.items()},
            "worst_iou": float(min(min(v) for v in ious.values())), "false_max": float(max(false)),
            "least_seen": float(min(seen)), "per_frame": per_frame}


def figure_change(a: dict, b: dict) -> tuple[float, float]:
    """The largest change of a scored IoU (per image and ink) and of an image's false stain area between two
    trees' :func:`figures`."""
    iou = [abs(x[1] - y[1]) for fa, fb in zip(a["per_frame"], b["per_frame"])
           for x, y in zip(fa["scores"], fb["scores"])]
    false = [abs(fa["false"] - fb["false"]) for fa, fb in zip(a["per_frame"], b["per_frame"])]
    return max(iou, default=0.0), max(false, default=0.0)


def run_tree(tree: Path, sets_file: Path, out: Path, repeat: int) -> dict:
    subprocess.run([sys.executable, "-c", WORKER, str(tree), str(sets_file), str(out), str(repeat), str(TIMED)],
                   check=True, cwd=tree)
    with open(out, "rb") as f:
        return pickle.load(f)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="git revision of the baseline (e.g. the commit before)")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=2, help="passes over the frames per round")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of baseline then this tree")
    ap.add_argument("--baseline-sim-only", action="store_true",
                    help="a baseline older than the photographs' config keys gets the simulator's frames only")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    sim, sim_truths, sim_config = sim_frames(args.seeds)
    sets = {"sim 640x480": dict(frames=sim, config=sim_config)}
    truths = {"sim 640x480": ("sim", sim_truths, sim_config)}
    for w, h in ((1280, 720), (1160, None)):
        frames, photo_truths, config = photo_frames(w, h)
        key = f"photos {w}x{h or round(870 * w / 1160)}"
        sets[key] = dict(frames=frames, config=config)
        truths[key] = ("photo", photo_truths, config)
    for s in sets.values():
        s["noisy"] = with_noise(s["frames"])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "baseline"
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(base), args.baseline],
                       check=True, capture_output=True)
        try:
            base_sets = {k: v for k, v in sets.items() if k.startswith("sim") or not args.baseline_sim_only}
            (tmp / "all.pkl").write_bytes(pickle.dumps(sets))
            (tmp / "base.pkl").write_bytes(pickle.dumps(base_sets))
            new_ms: dict[str, list] = {k: [] for k in sets}
            base_ms: dict[str, list] = {k: [] for k in base_sets}
            new_cpu: dict[str, list] = {k: [] for k in sets}
            base_cpu: dict[str, list] = {k: [] for k in base_sets}
            new_res = base_res = None
            ratios: dict[str, list] = {k: [] for k in base_sets}
            for _ in range(args.rounds):
                base_res = run_tree(base, tmp / "base.pkl", tmp / "b.out", args.repeat)
                new_res = run_tree(REPO, tmp / "all.pkl", tmp / "n.out", args.repeat)
                for k in base_ms:
                    base_ms[k] += base_res[k]["ms"]
                    base_cpu[k] += base_res[k]["cpu_ms"]
                    ratios[k].append(np.median(new_res[k]["cpu_ms"]) / np.median(base_res[k]["cpu_ms"]))
                for k in new_ms:
                    new_ms[k] += new_res[k]["ms"]
                    new_cpu[k] += new_res[k]["cpu_ms"]
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(base)], check=False)
    rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip()
    rows = []
    b, n = args.baseline, rev
    print(f"| frames (one core) | {b} latency p50 / p99 [ms] | {b} frames/s | {n} latency p50 / p99 [ms] | "
          f"{n} frames/s | CPU time ratio (rounds' median, range) | {b} worst IoU / largest false area | "
          f"{n} mean IoU per ink (worst) / largest false area (least seen) | largest IoU / false area change |")
    print("|---|---:|---:|---:|---:|---|---|---|---|")
    for k in sets:
        kind, t, config = truths[k]
        new_fig = figures(kind, new_res[k], t, config)
        p50, p99 = (float(np.percentile(new_ms[k], q)) for q in (50, 99))
        fps = 1e3 / float(np.median(new_cpu[k]))
        if k in base_ms:
            b50, b99 = (float(np.percentile(base_ms[k], q)) for q in (50, 99))
            b_fps = 1e3 / float(np.median(base_cpu[k]))
            base_fig = figures(kind, base_res[k], t, config)
            base_txt = f"{base_fig['worst_iou']:.2f} / {100 * base_fig['false_max']:.2f} %"
            r = np.array(ratios[k])
            ratio = f"{np.median(r):.2f}x ({r.min():.2f}-{r.max():.2f})"
            change = figure_change(base_fig, new_fig)
            change_txt = f"{change[0]:.3f} / {100 * change[1]:.3f} points"
        else:
            b50 = b99 = b_fps = float("nan")
            base_fig, base_txt, ratio, change, change_txt = None, "(keys unknown to it)", "-", None, "-"
        inks = ", ".join(f"{n} {v:.2f}" for n, v in new_fig["iou"].items())
        print(f"| {k} | {b50:.1f} / {b99:.1f} | {b_fps:.0f} | {p50:.1f} / {p99:.1f} | {fps:.0f} | {ratio} "
              f"| {base_txt} | {inks} ({new_fig['worst_iou']:.2f}) / {100 * new_fig['false_max']:.2f} % "
              f"(seen {new_fig['least_seen']:.0%}) | {change_txt} |")
        rows.append(dict(frames=k, baseline_ms=b50, baseline_p99_ms=b99, baseline_fps=b_fps, ms=p50, p99_ms=p99,
                         fps=fps, new=new_fig,
                         baseline=base_fig, largest_change=change))
    print()
    print(f"| photograph ({rev}, 1160x870) | " + " | ".join(PHOTO_INKS) + " | false stain area | board occluded |")
    print("|---|" + "---:|" * (len(PHOTO_INKS) + 2))
    full = next(r for r in rows if r["frames"].startswith("photos 1160"))
    for name, fr in zip(("straight", "sideangle", "highangle"), full["new"]["per_frame"]):
        cells = {ink: (f"{iou:.2f}" if seen >= 0.5 else f"({iou:.2f}: {seen:.0%} seen, glare)")
                 for ink, iou, seen in fr["scores"]}
        print(f"| {name} | " + " | ".join(cells.get(i, "-") for i in PHOTO_INKS)
              + f" | {100 * fr['false']:.2f} % | {100 * fr['occluded']:.1f} % |")
    sim_rows = next(r for r in rows if r["frames"].startswith("sim"))
    for which in ("baseline", "new"):
        fig = sim_rows[which]
        label = args.baseline if which == "baseline" else rev
        ious = [s[1] for fr in fig["per_frame"] for s in fr["scores"]]
        print(f"| sim seeds 1-{args.seeds} ({label}, 640x480) | blue {min(ious):.2f}-{max(ious):.2f} | | | | | "
              f"{100 * max(fr['false'] for fr in fig['per_frame']):.2f} % | "
              f"{100 * max(fr['occluded'] for fr in fig['per_frame']):.1f} % |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
