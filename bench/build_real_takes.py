"""Write the long real test set (:data:`lampskit.learn.takes.REAL_TAKES`) as demonstration and label files.

Usage: .venv/bin/python bench/build_real_takes.py --out DIR [--data MAT]

Builds every take from the four real recordings of
``../shared/data/wiping-demos/circular_wiping_dataset.mat`` (read there,
never copied) and writes ``DIR/<take>.csv`` (``t,x,y,z,qw,qx,qy,qz``,
what ``lamps segment`` and ``lamps learn`` read) and
``DIR/<take>_labels.csv`` (``t,label,stain``: ``periodic`` or
``transitional``, the wiping phase's number), atomically. The same inputs
give the same files (the pauses' jitter is seeded per take).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lampskit.learn.demo_io import write_demo_csv, write_labels_csv  # noqa: E402
from lampskit.learn.takes import REAL_TAKES, build_real_takes  # noqa: E402

REAL = ROOT.parent / "shared" / "data" / "wiping-demos" / "circular_wiping_dataset.mat"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--data", type=Path, default=REAL)
    a = ap.parse_args()
    if not a.data.is_file():
        print(f"build_real_takes: error: {a.data}: no such file (the wiping-demos dataset)", file=sys.stderr)
        return 1
    a.out.mkdir(parents=True, exist_ok=True)
    for recipe, take in zip(REAL_TAKES, build_real_takes(str(a.data))):
        stain = np.full(take.demo.n_samples, -1)
        for k, (i0, i1) in enumerate(take.wipes):
            stain[i0:i1] = k
        write_demo_csv(a.out / f"{take.name}.csv", take.demo)
        write_labels_csv(a.out / f"{take.name}_labels.csv", take.demo.t_s, take.true_periodic, stain)
        print(f"{take.name}: {take.demo.n_samples} samples, {take.demo.t_s[-1]:.1f} s, {len(take.wipes)} wiping "
              f"phases: {recipe.what}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
