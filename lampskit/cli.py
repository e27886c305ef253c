"""Command-line entry points of the skill-learning half (``lamps demo``, ``segment``, ``learn``, ...).

Each ``*_main(argv) -> int`` parses its own arguments. A
:class:`~lampskit.errors.LampsError` becomes one line on stderr
naming the problem and exit code 1; usage errors exit 2. Output files are
written only after everything they depend on succeeded, and atomically.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from lampskit.atomic import write_text_atomic
from lampskit.errors import LampsError

if TYPE_CHECKING:
    from lampskit.learn.bags import ArmKinematics

log = logging.getLogger("lamps")


class Progress:
    """A one-line progress display on stderr: redrawn on a terminal, a few lines otherwise."""

    def __init__(self, stream=None) -> None:
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last: tuple[str, int] = ("", -1)
        self._t0 = time.monotonic()

    def __call__(self, stage: str, done: int, total: int) -> None:
        pct = int(100 * done / max(total, 1))
        step = pct if self.tty else pct // 25 * 25
        if (stage, step) == self._last:
            return
        self._last = (stage, step)
        text = f"{stage}: {pct:3d}% ({done}/{total}) {time.monotonic() - self._t0:5.1f} s"
        if self.tty:
            self.stream.write("\r" + text + ("\n" if done >= total else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def _run(name: str, parser: argparse.ArgumentParser, argv: list[str], body: Callable[[argparse.Namespace], int]) -> int:
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if getattr(args, "verbose", False) else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return body(args)
    except LampsError as exc:
        print(f"lamps {name}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"lamps {name}: error: {exc}", file=sys.stderr)
        return 1


def _parser(name: str, description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=f"lamps {name}", description=description)
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens")
    return p


def _check_out_parent(path: Path) -> None:
    if not path.parent.is_dir():
        raise LampsError(f"{path}: the folder {path.parent} does not exist")


# --------------------------------------------------------------------------
# lamps demo-data


def demo_data_main(argv: list[str]) -> int:
    p = _parser("demo-data", "Write a synthetic, human-like multi-periodic wiping demonstration.")
    p.add_argument("--stains", type=int, default=4, help="number of stains wiped, 1-8 (default 4)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--rate", type=float, default=None, help="sample rate [Hz] (default drawn from 100-200)")
    p.add_argument("--noise", type=float, default=0.0004, help="position noise std [m] (default 0.0004)")
    p.add_argument("--revisit", action="store_true", help="wipe the first stain again at the end")
    p.add_argument("--human", action="store_true",
                   help="as people do in one take: lift-offs, a spot wiped again after one, a pause, a grip shift")
    p.add_argument("-o", "--output", type=Path, required=True, help="output file (.csv or .npz)")
    p.add_argument("--labels", type=Path, default=None, help="also write the true per-sample labels (CSV)")

    def body(a: argparse.Namespace) -> int:
        from lampskit.learn.demo_io import write_demo_csv, write_demo_npz, write_labels_csv
        from lampskit.learn.synth import synthesize_demo

        if a.output.suffix.lower() not in (".csv", ".npz"):
            raise LampsError(f"{a.output}: output must end in .csv or .npz")
        for path in filter(None, (a.output, a.labels)):
            _check_out_parent(path)
        s = synthesize_demo(a.stains, a.seed, a.rate, a.noise, a.revisit, a.human)
        (write_demo_csv if a.output.suffix.lower() == ".csv" else write_demo_npz)(a.output, s.demo)
        if a.labels:
            write_labels_csv(a.labels, s.demo.t_s, s.true_periodic, s.true_stain)
        print(
            f"wrote {a.output}: {s.demo.n_samples} samples, {s.demo.duration_s:.1f} s at {s.demo.rate_hz:.0f} Hz, "
            f"{len(s.strokes)} stains, {sum(k == 'periodic' for *_, k, _ in s.segments)} wiping phases"
            + (f"; labels {a.labels}" if a.labels else "")
        )
        return 0

    return _run("demo-data", p, argv, body)


# --------------------------------------------------------------------------
# lamps segment / evaluate-segmentation


def _add_segment_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("demo", help="demonstration file (.csv, .npz, QTM .tsv, or dataset.mat#INDEX)")
    p.add_argument("--method", choices=("optics", "kmeans", "affinity", "sklearn-optics"), default="optics")
    p.add_argument("--threshold", type=float, default=None, help="reachability threshold [m] (default automatic)")
    p.add_argument("--min-samples", type=int, default=None, help="OPTICS min_samples (default from the rate)")


def _segment(a: argparse.Namespace):
    from lampskit.learn.demo_io import read_demo
    from lampskit.learn.segmentation import segment

    demo = read_demo(a.demo)
    progress = Progress()
    seg = segment(
        demo,
        method=a.method,
        threshold=a.threshold,
        min_samples=a.min_samples,
        progress=lambda done, total: progress(f"{a.method}", done, total),
    )
    return demo, seg


def _segment_table(demo, seg) -> str:
    lines = [f"{'#':>3} {'kind':<12} {'cluster':>7} {'start':>6} {'end':>6} {'t0 [s]':>8} {'t1 [s]':>8}"]
    for i, s in enumerate(seg.segments):
        t1 = demo.t_s[s.end - 1]
        lines.append(
            f"{i:>3} {s.kind:<12} {s.cluster:>7} {s.start:>6} {s.end:>6} {demo.t_s[s.start]:>8.2f} {t1:>8.2f}"
        )
    n_per = sum(s.kind == "periodic" for s in seg.segments)
    thr = "n/a" if seg.threshold is None else f"{seg.threshold:.4g} m"
    lines.append(f"{len(seg.segments)} segments, {n_per} periodic; method {seg.method}, threshold {thr}")
    return "\n".join(lines)


def segment_main(argv: list[str]) -> int:
    p = _parser("segment", "Segment a demonstration into periodic and transitional movement primitives.")
    _add_segment_options(p)
    p.add_argument("--json", type=Path, default=None, help="write segments, threshold, reachability and each "
                                                             "cut's margin as JSON")
    p.add_argument("--plot", type=Path, default=None, metavar="STEM",
                   help="write STEM.png (reachability, speed, height above the stroke surface, segments coloured) "
                        "and STEM.mcap (the take with a /take/segments channel)")

    def body(a: argparse.Namespace) -> int:
        for out in (a.json, a.plot):
            if out:
                _check_out_parent(out)
        demo, seg = _segment(a)
        print(_segment_table(demo, seg))
        if a.json:
            write_text_atomic(a.json, json.dumps(seg.to_dict()) + "\n")
            print(f"wrote {a.json}")
        if a.plot:
            from lampskit.learn.segment_plot import write_segment_mcap, write_segment_png

            stem = a.plot.with_suffix("") if a.plot.suffix in (".png", ".mcap") else a.plot
            for path in (write_segment_png(demo, seg, stem.with_name(stem.name + ".png")),
                         write_segment_mcap(demo, seg, stem.with_name(stem.name + ".mcap"))):
                print(f"wrote {path}")
        return 0

    return _run("segment", p, argv, body)


def evaluate_main(argv: list[str]) -> int:
    p = _parser(
        "evaluate-segmentation",
        "Frame accuracy (periodic vs transitional) of a segmentation against labels; "
        "the labels are read only after segmenting and never steer it.",
    )
    _add_segment_options(p)
    p.add_argument("--labels", required=True, help="labels file (.csv with 'label', .npz, or dataset.mat#INDEX)")
    p.add_argument("--json", type=Path, default=None, help="write the scores as JSON")

    def body(a: argparse.Namespace) -> int:
        from lampskit.learn.demo_io import read_labels
        from lampskit.learn.segmentation_scores import frame_accuracy

        if a.json:
            _check_out_parent(a.json)
        demo, seg = _segment(a)
        truth = read_labels(a.labels, demo.n_samples)
        acc = frame_accuracy(seg, truth)
        true_runs = int(np.sum(np.diff(np.r_[0, truth.astype(int)]) == 1))
        found = sum(s.kind == "periodic" for s in seg.segments)
        print(_segment_table(demo, seg))
        print(f"frame accuracy {acc:.4f}; periodic segments found {found}, labelled {true_runs}")
        if a.json:
            scores = {"demo": str(a.demo), "method": a.method, "frame_accuracy": acc,
                      "periodic_segments_found": found, "periodic_segments_labelled": true_runs}
            write_text_atomic(a.json, json.dumps(scores, indent=1) + "\n")
        return 0

    return _run("evaluate-segmentation", p, argv, body)


# --------------------------------------------------------------------------
# lamps learn


def learn_main(argv: list[str], arm: Callable[[], ArmKinematics] | None = None) -> int:
    """``lamps learn``; ``arm`` builds the arm that robot recordings are read with (the cell's command passes the
    described iiwa: :func:`launch.learn.described_arm`), without it only demonstration files are read."""
    p = _parser("learn", "Segment demonstrations, learn their periodic and transitional MPs, save a skill file. "
                         "Several demonstrations of one skill (same board, same phases in the same order) are "
                         "fused MP by MP (GMM-GMR over all of them) and their spread recorded.")
    p.add_argument("demo", nargs="+", help="demonstration file(s) (.csv, .npz, QTM .tsv, or dataset.mat#INDEX) or "
                                           "robot recording(s): a rosbag2 folder, an .mcap or .db3 file")
    p.add_argument("-o", "--output", type=Path, required=True, help="skill file to write (JSON)")
    p.add_argument("--method", choices=("optics", "kmeans", "affinity", "sklearn-optics"), default="optics")
    p.add_argument("--plots", type=Path, default=None, help="folder for the paper's Figs. 4-7 as PNG (first demo)")
    p.add_argument("--segments", type=Path, default=None, metavar="FILE",
                   help="learn from these segments (the JSON of 'lamps segment --json', edited: merge, split at a "
                        "time, relabel) instead of segmenting; one demo only")
    _recording_options(p)

    def body(a: argparse.Namespace) -> int:
        from lampskit.core.skill import save_skill
        from lampskit.learn.learn import learn_skill_from_demos

        _check_out_parent(a.output)
        demos = _read_demos(a, arm)
        if a.segments is not None:
            from lampskit.learn.learn import learn_skill
            from lampskit.learn.segments_file import read_segments

            if len(demos) != 1:
                raise LampsError(f"--segments applies to one demonstration, got {len(demos)}")
            skill, seg = learn_skill(demos[0], read_segments(a.segments, demos[0]), progress=Progress())
            segs = [seg]
        else:
            skill, segs = learn_skill_from_demos(demos, method=a.method, progress=Progress())
        save_skill(a.output, skill)
        print(_skill_summary(skill))
        print(f"wrote {a.output}")
        if a.plots:
            from lampskit.figures.demo import write_figures

            a.plots.mkdir(parents=True, exist_ok=True)
            for path in write_figures(demos[0], skill, segs[0], a.plots, progress=Progress()):
                print(f"wrote {path}")
        return 0

    return _run("learn", p, argv, body)


def _recording_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("robot recordings", "which path to learn from a rosbag2 folder, an MCAP file or the "
                                                 "cell's recording.mcap (docs/real-robot.md#teaching-on-the-robot)")
    g.add_argument("--topic", help="topic to read (default: the one LBRState, JointState, cell robot/state or "
                                   "PoseStamped topic, in that order; /tf with --frame)")
    g.add_argument("--frame", help="the frame to learn from /tf (and /tf_static)")
    g.add_argument("--base-frame", help="express --frame in this frame (default: the root of its tree)")
    g.add_argument("--tool-offset", metavar="X,Y,Z", type=_xyz,
                   help="pad centre [m] in the flange frame (joints; default: the described eraser's pad) or in the "
                        "recorded frame (poses; default 0,0,0)")
    g.add_argument("--start", type=float, metavar="S", help="learn from S seconds after the topic's first sample")
    g.add_argument("--end", type=float, metavar="S", help="learn up to S seconds after the topic's first sample")
    g.add_argument("--max-gap", type=float, metavar="S",
                   help="longest gap between samples [s] (default: 5 sample periods, at least 0.05 s)")


def _xyz(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not X,Y,Z in metres (e.g. 0,0,0.035)") from None
    return x, y, z


def _read_demos(a: argparse.Namespace, arm: Callable[[], ArmKinematics] | None) -> list:
    """Every ``a.demo``: robot recordings through :mod:`lampskit.learn.bags` with the arm ``arm()`` builds, files
    by :func:`~lampskit.learn.demo_io.read_demo`; the recording options only for recordings."""
    from lampskit.learn.bags import BagOptions, is_recording, read_recording_demo
    from lampskit.learn.demo_io import read_demo

    options = BagOptions(a.topic, a.frame, a.base_frame, a.tool_offset, a.start, a.end, a.max_gap)
    given = [f"--{k.replace('_', '-')}" for k in ("topic", "frame", "base_frame", "tool_offset", "start", "end",
                                                  "max_gap") if getattr(a, k) is not None]
    recordings = [spec for spec in a.demo if is_recording(spec)]
    if given and not recordings:
        raise LampsError(f"{', '.join(given)}: only for robot recordings (a rosbag2 folder, .mcap, .db3), "
                         f"and {', '.join(a.demo)} holds none")
    if not recordings:
        return [read_demo(spec) for spec in a.demo]
    if arm is None:
        raise LampsError(f"{', '.join(recordings)}: a robot recording is read with an arm's description, and none "
                         "was given (the cell's 'lamps learn' gives its arm)")
    kinematics = arm()
    return [read_recording_demo(spec, kinematics, options) if is_recording(spec) else read_demo(spec)
            for spec in a.demo]


def _skill_summary(skill) -> str:
    spread = skill.source.get("spread", {})
    n_demos = len(skill.source.get("demos", [])) or 1
    lines = [f"skill: {len(skill.periodic)} periodic MP(s), {len(skill.transitional)} transitional MP(s)"
             + (f", fused from {n_demos} demonstrations (spread: path RMS between them)" if n_demos > 1 else "")]
    for k, e in enumerate(skill.periodic):
        mp = e.mp
        line = (f"  periodic  seg {e.segment:>2}: {mp.omega_rad_s / (2 * np.pi):.3f} Hz, "
                f"r = {mp.amplitude_m * 100:.1f} cm, {e.n_cycles:.1f} cycles")
        if spread.get("periodic"):
            sp = spread["periodic"][k]
            line += f"; spread {sp['path_rms_m'] * 1000:.1f} mm, {sp['freq_std_hz']:.3f} Hz"
        lines.append(line)
    for k, e in enumerate(skill.transitional):
        line = (f"  transit.  seg {e.segment:>2}: {e.mp.demo_duration_s:.2f} s,"
                f" {np.linalg.norm(e.mp.demo_displacement_m) * 100:.1f} cm")
        if spread.get("transitional"):
            sp = spread["transitional"][k]
            line += f"; spread {sp['path_rms_m'] * 1000:.1f} mm, {sp['duration_std_s']:.2f} s"
        lines.append(line)
    return "\n".join(lines)


# --------------------------------------------------------------------------
# lamps plan


def _parse_stains(text: str):
    from lampskit.core.planner_types import Stain

    stains = []
    for i, item in enumerate(filter(None, (s.strip() for s in text.split(";")))):
        try:
            x, y, size = (float(v) for v in item.split(","))
        except ValueError:
            raise LampsError(f"--stains item {i} {item!r}: expected 'x,y,size' in metres") from None
        stains.append(Stain(i, np.array([x, y]), size))
    return stains


def plan_main(argv: list[str]) -> int:
    p = _parser("plan", "Plan a learned skill over stains on a board and roll it out at 1 kHz.")
    p.add_argument("skill", type=Path, help="skill file from 'lamps learn'")
    p.add_argument("--stains", required=True, help="'x,y,size; x,y,size; ...' in the board frame [m]")
    p.add_argument("--start", default="0,0", help="start position 'x,y' in the board frame [m] (default 0,0)")
    p.add_argument("--cycles", type=float, default=None, help="cycles per stain (kappa's stand-in)")
    p.add_argument("--rate", type=float, default=1000.0, help="rollout rate [Hz] (default 1000)")
    p.add_argument("--csv", type=Path, default=None, help="write the rolled-out reference as CSV")

    def body(a: argparse.Namespace) -> int:
        from lampskit.core.planner import plan
        from lampskit.core.rollout import rollout
        from lampskit.core.skill import load_skill

        if a.csv:
            _check_out_parent(a.csv)
        if not 50.0 <= a.rate <= 10000.0:
            raise LampsError(f"--rate {a.rate!r}: must be between 50 and 10000 Hz")
        skill = load_skill(a.skill)
        try:
            start = np.array([float(v) for v in a.start.split(",")])
        except ValueError:
            raise LampsError(f"--start {a.start!r}: expected 'x,y' in metres") from None
        pl = plan(skill, _parse_stains(a.stains), start)
        ro = rollout(skill, pl, (start, np.zeros(2), np.zeros(2)), dt_s=1.0 / a.rate, cycles_per_stain=a.cycles)
        print(f"order {list(pl.order)}; {len(ro.t_s)} samples, {ro.t_s[-1]:.2f} s")
        for w, spec in zip(pl.wipes, ro.transitions):
            print(
                f"  stain {w.stain.id}: r = {w.amplitude_m * 100:.1f} cm, transition {spec.duration_s:.2f} s,"
                f" entry phase {np.degrees(spec.entry_phase_rad):.0f} deg"
            )
        if a.csv:
            data = np.column_stack([ro.t_s, ro.position_m, ro.velocity_m_s, ro.acceleration_m_s2])
            head = "t,x,y,vx,vy,ax,ay"
            rows = [",".join(f"{v:.9g}" for v in row) + f",{k},{s}" for row, k, s in zip(data, ro.kind, ro.stain)]
            write_text_atomic(a.csv, head + ",kind,stain\n" + "\n".join(rows) + "\n")
            print(f"wrote {a.csv}")
        return 0

    return _run("plan", p, argv, body)


# --------------------------------------------------------------------------
# lamps demo: the embedded default


def demo_main(argv: list[str]) -> int:
    p = _parser(
        "demo",
        "The embedded default: synthesize a wiping demonstration, learn it, write the paper's figures and "
        "the skill file, then generalise the skill to a new board with other stains.",
    )
    p.add_argument("--stains", type=int, default=4, help="stains in the demonstration (default 4)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default runs/demo-<time>)")

    def body(a: argparse.Namespace) -> int:
        from lampskit.core.skill import save_skill
        from lampskit.figures.demo import write_figures, write_generalisation_figure
        from lampskit.learn.demo_io import write_demo_csv, write_labels_csv
        from lampskit.learn.learn import learn_skill
        from lampskit.learn.segmentation_scores import frame_accuracy
        from lampskit.learn.synth import synthesize_demo

        out = a.out or Path("runs") / time.strftime("demo-%Y%m%d-%H%M%S")
        s = synthesize_demo(a.stains, a.seed)
        out.mkdir(parents=True, exist_ok=True)
        print(f"demonstration: {s.demo.n_samples} samples, {s.demo.duration_s:.1f} s, {len(s.strokes)} stains")
        skill, seg = learn_skill(s.demo, progress=Progress())
        acc = frame_accuracy(seg, s.true_periodic)
        print(_segment_table(s.demo, seg))
        print(f"segmentation frame accuracy vs truth: {acc:.4f}")
        print(_skill_summary(skill))
        pl, ro = _generalise_to_new_board(skill, a.seed)
        paths = write_demo_csv(out / "demo.csv", s.demo), write_labels_csv(
            out / "labels.csv", s.demo.t_s, s.true_periodic, s.true_stain
        )
        figs = write_figures(s.demo, skill, seg, out, progress=Progress())
        figs.append(write_generalisation_figure(skill, pl, ro, out / "generalisation.png"))
        skill_path = save_skill(out / "skill.json", skill)
        summary = _demo_summary(s, seg, acc, pl, ro)
        write_text_atomic(out / "summary.json", json.dumps(summary, indent=1) + "\n")
        for path in [*paths, *figs, skill_path, out / "summary.json"]:
            print(f"wrote {path}")
        print(
            f"new board: stains visited {list(pl.order)} in {ro.t_s[-1]:.1f} s; at the MP junctions the acceleration "
            f"steps at most {summary['max_junction_accel_step_ratio']:.2f}x an ordinary tick's "
            f"(continuous: <= ~1); peak acceleration {summary['peak_accel_m_s2']:.1f} m/s^2"
        )
        return 0

    return _run("demo", p, argv, body)


def _generalise_to_new_board(skill, seed: int):
    """Plan and roll out ``skill`` over 3 random stains (seeded) of a board it has never seen: (plan, rollout)."""
    from lampskit.core.planner import plan
    from lampskit.core.planner_types import Stain
    from lampskit.core.rollout import rollout

    rng = np.random.default_rng(seed + 1000)
    new_board = [Stain(i, rng.uniform([0.15, 0.15], [0.95, 0.65]), float(rng.uniform(0.04, 0.1))) for i in range(3)]
    start = np.array([0.05, 0.05])
    pl = plan(skill, new_board, start)
    return pl, rollout(skill, pl, (start, np.zeros(2), np.zeros(2)))


def _demo_summary(s, seg, accuracy: float, pl, ro) -> dict:
    """summary.json of ``lamps demo``: the segmentation against the truth and the new board's rollout."""
    from lampskit.core.rollout import junction_step_ratios

    ratios = junction_step_ratios(ro)
    return {
        "demo_samples": s.demo.n_samples,
        "segmentation_frame_accuracy": accuracy,
        "periodic_segments": sum(x.kind == "periodic" for x in seg.segments),
        "true_periodic_segments": len(s.strokes),
        "new_board_order": list(pl.order),
        "rollout_duration_s": float(ro.t_s[-1]),
        "max_junction_accel_step_ratio": float(ratios[:, 2].max()) if len(ratios) else 0.0,
        "peak_accel_m_s2": float(np.linalg.norm(ro.acceleration_m_s2, axis=1).max()),
    }
