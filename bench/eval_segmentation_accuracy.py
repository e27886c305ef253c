"""Segmentation quality: frame accuracy and periodic segment counts, OPTICS vs the baselines.

Usage: .venv/bin/python bench/eval_segmentation_accuracy.py [--seeds N] [--quick] [--json OUT]

- synthetic: ``synthesize_demo(n, seed)`` for n = 2..6 stains and ``--seeds``
  seeds each (the ground truth comes with the generator);
- synthetic human takes: ``synthesize_demo(n, seed, human=True)`` for n = 2..8
  and ``--seeds`` seeds (lift-offs, a revisit, a pause, a grip shift);
- real: the four hand-labelled demonstrations in
  ``../shared/data/wiping-demos/circular_wiping_dataset.mat`` (skipped when
  absent; read from there, never copied);
- messy generated takes: ``draw_messy_take(seed)`` for ``--messy`` seeds (:mod:`lampskit.learn.synth_messy`:
  wandering, drifting strokes with pauses and slow strokes, hops leaving mid-stroke along a tilted normal,
  lift-offs, slides, noise and dropped samples at 100-1000 Hz), OPTICS only, per take;
- public carrot grating (``--grating FILE``, optics only, per demo): ``test-data/Grating/CarrotGrating_robot.mat``
  of the public repository nbfigueroa/ICSC-HMM (12 kinesthetic demonstrations of grating a carrot, 7-D pose,
  hand labels 1 reach / 2 grating / 3 retract; no rate stated, read as 100 Hz). Fetch it yourself and keep it
  out of the repository: the repository's licence (SimPL-2.0) is a code licence and says nothing of the data;
- real long takes: :data:`lampskit.learn.takes.REAL_TAKES`, several wipes
  chained from those recordings (lift-offs and returns, spots 6-30 cm apart,
  pauses, a shift inside a wipe), per take: true and found wiping phases,
  frame accuracy and the largest boundary error [s] (each true wiping
  phase's start and end against the nearest found periodic boundary).

For each method (optics; the baselines kmeans, affinity and sklearn-optics,
plain scikit-learn OPTICS read at a fixed 40 mm threshold) it prints the
frame accuracy (periodic vs transitional) and how many demos got exactly the
true number of periodic segments, all in the same run. Nothing here looks at
the labels before scoring.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lampskit.learn.demo_io import read_demo, read_labels  # noqa: E402
from lampskit.learn.segmentation import segment  # noqa: E402
from lampskit.learn.segmentation_scores import frame_accuracy, true_segment_count  # noqa: E402
from lampskit.learn.synth import synthesize_demo  # noqa: E402
from lampskit.learn.takes import build_real_takes  # noqa: E402

REAL = ROOT.parent / "shared" / "data" / "wiping-demos" / "circular_wiping_dataset.mat"
METHODS = ("optics", "kmeans", "affinity", "sklearn-optics")


def _score(demo, truth: np.ndarray, method: str) -> tuple[float, int, int]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seg = segment(demo, method=method)
    found = sum(s.kind == "periodic" for s in seg.segments)
    return frame_accuracy(seg, truth), found, true_segment_count(truth)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--quick", action="store_true", help="one seed (lamps bench --quick)")
    ap.add_argument("--messy", type=int, default=20, help="messy generated takes scored (seeds 0..N-1)")
    ap.add_argument("--grating", type=Path, default=None, help="CarrotGrating_robot.mat of nbfigueroa/ICSC-HMM")
    a = ap.parse_args()
    if a.quick:
        a.seeds = 1
    sets = {"synthetic": [synthesize_demo(n, s) for n in range(2, 7) for s in range(a.seeds)],
            "synthetic human": [synthesize_demo(n, s, human=True) for n in range(2, 9) for s in range(a.seeds)]}
    rows: dict[str, dict[str, list]] = {m: {k: [] for k in sets} for m in METHODS}
    real_rows = []
    for name, cases in sets.items():
        for syn in cases:
            for m in METHODS:
                rows[m][name].append(_score(syn.demo, syn.true_periodic, m))
    if REAL.is_file():
        for i in range(4):
            demo = read_demo(f"{REAL}#{i}")
            truth = read_labels(f"{REAL}#{i}", demo.n_samples)
            real_rows.append({m: _score(demo, truth, m) for m in METHODS})
    print("| method | synthetic: mean / min frame accuracy, exact count | synthetic human takes (2-8 stains): "
          "mean / min accuracy, exact count | real demos 0-3: frame accuracy | real: exact count |")
    print("|---|---|---|---|---|")
    out = {}
    for m in METHODS:
        cells = []
        for name in sets:
            acc = np.array([r[0] for r in rows[m][name]])
            exact = sum(r[1] == r[2] for r in rows[m][name])
            cells.append(f"{acc.mean():.3f} / {acc.min():.3f}, {exact}/{len(acc)}")
            out.setdefault(m, {})[name] = {"accuracy": acc.tolist(), "exact": exact}
        real = " / ".join(f"{r[m][0]:.3f}" for r in real_rows) or "absent"
        real_exact = f"{sum(r[m][1] == r[m][2] for r in real_rows)}/{len(real_rows)}" if real_rows else "-"
        print(f"| {m} | " + " | ".join(cells) + f" | {real} | {real_exact} |")
        out[m]["real"] = [r[m] for r in real_rows]
    out["messy"] = _messy_table(a.messy)
    if a.grating is not None:
        out["grating"] = _grating_table(a.grating)
    if REAL.is_file():
        out["takes"] = _takes_table()
    if a.json:
        a.json.write_text(json.dumps(out, indent=1))
    return 0


def _boundary_error_s(seg, take) -> float:
    """Largest distance [s] from a true wiping phase's start or end to the nearest found periodic boundary."""
    t = take.demo.t_s
    found = [b for s in seg.segments if s.kind == "periodic" for b in (t[s.start], t[min(s.end, len(t) - 1)])]
    if not found:
        return float("inf")
    true = [t[i] for i0, i1 in take.wipes for i in (i0, i1 - 1)]
    return max(min(abs(x - f) for f in found) for x in true)


def _messy_table(n: int) -> dict:
    from lampskit.learn.synth_messy import draw_messy_take

    print("\nmessy generated takes (lampskit/learn/synth_messy.py, draw_messy_take(seed)), optics\n")
    print("| seed | rate [Hz] | samples | true wiping phases | found | frame accuracy |")
    print("|---:|---:|---:|---:|---:|---:|")
    out = {}
    for seed in range(n):
        take = draw_messy_take(seed)
        acc, found, true = _score(take.demo, take.true_periodic, "optics")
        out[seed] = {"rate_hz": take.demo.rate_hz, "true": true, "found": found, "accuracy": acc}
        print(f"| {seed} | {take.demo.rate_hz:.0f} | {take.demo.n_samples} | {true} | {found} | {acc:.3f} |")
    exact = sum(r["found"] == r["true"] for r in out.values())
    accs = [r["accuracy"] for r in out.values()]
    if accs:
        print(f"\nexact count {exact}/{n}; frame accuracy mean {np.mean(accs):.3f}, min {np.min(accs):.3f}")
    return out


def _grating_table(path: Path) -> dict:
    from scipy.io import loadmat

    from lampskit.learn.demo import Demonstration

    data = loadmat(str(path), squeeze_me=True)
    print(f"\npublic carrot grating demonstrations ({path.name}, read as 100 Hz; label 2 periodic), optics\n")
    print("| demo | samples | labelled periodic | found | frame accuracy | smallest cut margin |")
    print("|---:|---:|---:|---:|---:|---:|")
    out = {}
    for i, (x, labels) in enumerate(zip(data["Data"], data["True_states"])):
        x = np.asarray(x, dtype=float)
        truth = np.asarray(labels).astype(int) == 2
        demo = Demonstration(np.arange(len(x)) / 100.0, x[:, :3], None, f"{path.name}#{i}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            seg = segment(demo)
        found = sum(s.kind == "periodic" for s in seg.segments)
        acc = frame_accuracy(seg, truth)
        margin = min((c["margin"] for c in seg.cuts if c["margin"] is not None and c["left"] != c["right"]
                      and "continuity" in c), default=None)
        out[i] = {"true": true_segment_count(truth), "found": found, "accuracy": acc, "margin": margin}
        shown = "-" if margin is None else f"{margin:+.2f}"
        print(f"| {i} | {len(x)} | {true_segment_count(truth)} | {found} | {acc:.3f} | {shown} |")
    exact = sum(r["found"] == r["true"] for r in out.values())
    print(f"\nexact count {exact}/{len(out)}")
    return out


def _takes_table() -> dict:
    takes = build_real_takes(str(REAL))
    print("\nreal long takes (chained from the four recordings, lampskit/learn/takes.py)\n")
    print("| take | samples | true wiping phases | " + " | ".join(f"{m}: found / accuracy / worst boundary [s]"
                                                          for m in METHODS) + " |")
    print("|---|---:|---:|" + "---|" * len(METHODS))
    out = {}
    for take in takes:
        cells, out[take.name] = [], {}
        for m in METHODS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                seg = segment(take.demo, method=m)
            found = sum(s.kind == "periodic" for s in seg.segments)
            acc, err = frame_accuracy(seg, take.true_periodic), _boundary_error_s(seg, take)
            cells.append(f"{found} / {acc:.3f} / {err:.1f}")
            out[take.name][m] = {"found": found, "accuracy": acc, "boundary_error_s": err}
        print(f"| {take.name} | {take.demo.n_samples} | {len(take.wipes)} | " + " | ".join(cells) + " |")
    return out


if __name__ == "__main__":
    sys.exit(main())
