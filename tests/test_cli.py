"""The ``lamps`` command line: the README's main job, every subcommand, and bad input.

Bad input must give one clear line naming the problem, a non-zero exit and
no output file (not even a partial one).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from runtime.cli import COMMANDS, main

from .conftest import REAL_DEMOS, REPO


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def demo_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("demo")
    assert main(["demo-data", "--stains", "3", "--seed", "2", "-o", str(folder / "d.csv"),
                 "--labels", str(folder / "l.csv")]) == 0
    return folder / "d.csv", folder / "l.csv"


@pytest.fixture(scope="module")
def skill_file(demo_files, tmp_path_factory):
    path = tmp_path_factory.mktemp("skill") / "skill.json"
    assert main(["learn", str(demo_files[0]), "-o", str(path)]) == 0
    return path


def test_help_lists_commands_and_unknown_command_fails(capsys):
    code, out, _ = run(["--help"], capsys)
    assert code == 0 and "segment" in out and "learn" in out
    code, _, err = run(["frobnicate"], capsys)
    assert code == 2 and "unknown command 'frobnicate'" in err


def test_version_names_lamps_and_the_libraries_a_bug_report_needs(capsys):
    from importlib.metadata import version

    code, out, _ = run(["--version"], capsys)
    assert code == 0 and out.startswith(f"lamps {version('lamps')} (python ")
    assert f"eclipse-zenoh {version('eclipse-zenoh')}" in out and f"pin {version('pin')}" in out


def test_rust_log_shows_zenohs_own_log(tmp_path):
    code = ("from runtime.config import ZenohSettings\nfrom runtime.session import ServiceNode\n"
            "with ServiceNode('sim', ZenohSettings(listen=('tcp/127.0.0.1:0',), robot_id='logtest')):\n    pass\n")
    quiet = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60)
    loud = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60,
                          env={**os.environ, "RUST_LOG": "zenoh=info", "NO_COLOR": "1"})
    assert quiet.returncode == 0 and loud.returncode == 0, quiet.stderr + loud.stderr
    said = lambda r: r.stdout + r.stderr  # noqa: E731  (Zenoh's own log writer uses stdout)
    assert "Zenoh can be reached at" not in said(quiet) and "Zenoh can be reached at" in said(loud), said(loud)


def test_console_script_runs_as_a_process():
    res = subprocess.run([sys.executable, "-m", "runtime.cli", "segment", "--help"],
                         capture_output=True, text=True, cwd=REPO, timeout=120)
    assert res.returncode == 0 and "--method" in res.stdout


def test_segment_prints_table_and_writes_json(demo_files, tmp_path, capsys):
    out_json = tmp_path / "seg.json"
    code, out, _ = run(["segment", str(demo_files[0]), "--json", str(out_json)], capsys)
    assert code == 0
    assert "3 periodic" in out
    data = json.loads(out_json.read_text())
    assert {"segments", "threshold", "reachability"} <= set(data)
    segs = data["segments"]
    assert segs[0]["start"] == 0 and all(a["end"] == b["start"] for a, b in zip(segs, segs[1:]))
    assert sum(s["kind"] == "periodic" for s in segs) == 3


@pytest.mark.parametrize("method", ["kmeans", "affinity"])
def test_segment_baselines_run(demo_files, capsys, method):
    code, out, _ = run(["segment", str(demo_files[0]), "--method", method], capsys)
    assert code == 0 and f"method {method}" in out


def test_evaluate_segmentation_reports_accuracy(demo_files, capsys):
    code, out, _ = run(["evaluate-segmentation", str(demo_files[0]), "--labels", str(demo_files[1])], capsys)
    assert code == 0
    acc = float(out.split("frame accuracy ")[1].split(";")[0])
    assert acc >= 0.95
    assert "periodic segments found 3, labelled 3" in out


@pytest.mark.realdata
def test_evaluate_segmentation_on_a_real_demo(capsys):
    if not REAL_DEMOS.is_file():
        pytest.skip(f"real data absent: {REAL_DEMOS}")
    code, out, _ = run(["evaluate-segmentation", f"{REAL_DEMOS}#0", "--labels", f"{REAL_DEMOS}#0"], capsys)
    assert code == 0 and "periodic segments found 1, labelled 1" in out


def test_learn_writes_a_loadable_skill(skill_file):
    from lampskit.core.skill import load_skill

    skill = load_skill(skill_file)
    assert len(skill.periodic) == 3 and len(skill.transitional) >= 2


def test_plan_rolls_out_and_writes_csv(skill_file, tmp_path, capsys):
    csv = tmp_path / "ref.csv"
    code, out, _ = run(["plan", str(skill_file), "--stains", "0.3,0.3,0.08; 0.7,0.4,0.06", "--cycles", "2",
                        "--csv", str(csv)], capsys)
    assert code == 0 and "order" in out
    data = np.genfromtxt(csv, delimiter=",", skip_header=1, usecols=range(7))
    assert data.shape[1] == 7 and len(data) > 1000
    assert np.all(np.diff(data[:, 0]) > 0)


def _bad(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(
    "content, match",
    [
        ("", "empty"),
        ("t,x,y\n0,0,0\n", "missing column"),
        ("t,x,y,z\n" + "".join(f"{i / 100},0,0,0\n" for i in range(20)), "too short"),
        ("t,x,y,z\n" + "".join(f"{i / 100},{'nan' if i == 99 else np.sin(i / 10)},0,0\n" for i in range(300)), "NaN"),
        ("t,x,y,z\n" + "".join(f"{i / 100},{'inf' if i == 9 else 0},0,0\n" for i in range(300)), "inf"),
        ("t,x,y,z\n" + "".join(f"{(300 - i) / 100},0,0,0\n" for i in range(300)), "increase strictly"),
    ],
)
@pytest.mark.parametrize("command", ["learn", "segment"])
def test_bad_demo_fails_cleanly_without_output(tmp_path, capsys, content, match, command):
    demo = _bad(tmp_path, "bad.csv", content)
    out = tmp_path / "out.json"
    args = [command, demo, "-o", str(out)] if command == "learn" else [command, demo, "--json", str(out)]
    code, _, err = run(args, capsys)
    assert code == 1
    assert match in err and err.startswith(f"lamps {command}: error:")
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["bad.csv"]  # no temporary left behind


def test_demo_without_periodic_part_fails_cleanly(tmp_path, capsys):
    t = np.arange(600) / 100.0
    rows = "".join(f"{ti},{0.1 * ti},{0.05 * ti},0.3\n" for ti in t)  # a straight sweep
    demo = _bad(tmp_path, "line.csv", "t,x,y,z\n" + rows)
    out = tmp_path / "skill.json"
    code, _, err = run(["learn", demo, "-o", str(out)], capsys)
    assert code == 1 and "periodic" in err
    assert not out.exists()


def test_missing_output_folder_and_bad_skill(tmp_path, capsys, demo_files):
    code, _, err = run(["learn", str(demo_files[0]), "-o", str(tmp_path / "no" / "skill.json")], capsys)
    assert code == 1 and "does not exist" in err
    bad = _bad(tmp_path, "skill.json", json.dumps({"format": "lamps-skill", "version": 99}))
    code, _, err = run(["plan", bad, "--stains", "0.3,0.3,0.05"], capsys)
    assert code == 1 and "unknown skill file version 99" in err
    bad = _bad(tmp_path, "skill2.json", "{not json")
    code, _, err = run(["plan", bad, "--stains", "0.3,0.3,0.05"], capsys)
    assert code == 1 and "not valid JSON" in err


@pytest.mark.parametrize(
    "extra, match",
    [(["--rate", "0"], "--rate"), (["--rate", "inf"], "--rate"), (["--cycles", "nan"], "cycles_per_stain"),
     (["--cycles", "-1"], "cycles_per_stain")],
)
def test_bad_plan_options_fail_cleanly(skill_file, tmp_path, capsys, extra, match):
    csv = tmp_path / "ref.csv"
    code, _, err = run(["plan", str(skill_file), "--stains", "0.3,0.3,0.05", "--csv", str(csv), *extra], capsys)
    assert code == 1 and match in err and err.startswith("lamps plan: error:")
    assert not csv.exists()


def test_bad_seed_and_stain_count_fail_before_writing(tmp_path, capsys):
    code, _, err = run(["demo-data", "--seed", "-1", "-o", str(tmp_path / "d.csv")], capsys)
    assert code == 1 and "seed must be a non-negative integer" in err
    code, _, err = run(["demo", "--stains", "0", "--out", str(tmp_path / "run")], capsys)
    assert code == 1 and "n_stains" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_learn_with_plots_on_a_demo_without_transitions(tmp_path, capsys):
    t = np.arange(800) / 100.0
    rows = "".join(f"{ti},{0.5 + 0.05 * np.cos(2 * np.pi * ti)},{0.4 + 0.05 * np.sin(2 * np.pi * ti)},0.3\n"
                   for ti in t)
    demo = _bad(tmp_path, "circle.csv", "t,x,y,z\n" + rows)
    code, out, err = run(["learn", demo, "-o", str(tmp_path / "skill.json"), "--plots", str(tmp_path / "fig")],
                         capsys)
    assert code == 0, err
    assert (tmp_path / "skill.json").is_file()
    assert sorted(p.name for p in (tmp_path / "fig").iterdir()) == ["fig4_reachability.png",
                                                                     "fig5_segmentation_methods.png"]


def test_bad_stains_argument(skill_file, capsys):
    code, _, err = run(["plan", str(skill_file), "--stains", "0.3,0.3"], capsys)
    assert code == 1 and "expected 'x,y,size'" in err
    code, _, err = run(["plan", str(skill_file), "--stains", "0.3,0.3,-1"], capsys)
    assert code == 1 and "size_m must be a positive number" in err


@pytest.mark.slow
def test_readme_main_job_runs(tmp_path):
    """The README's main command (the embedded default) completes and writes its outputs."""
    res = subprocess.run([sys.executable, "-m", "runtime.cli", "demo", "--out", str(tmp_path / "run")],
                         capture_output=True, text=True, cwd=REPO, timeout=600)
    assert res.returncode == 0, res.stderr
    names = {p.name for p in (tmp_path / "run").iterdir()}
    assert {"skill.json", "demo.csv", "labels.csv", "summary.json", "fig4_reachability.png",
            "fig5_segmentation_methods.png", "fig6_transition_vs_target_crossing.png",
            "fig7_transition_entry_phases.png", "generalisation.png"} <= names
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["periodic_segments"] == summary["true_periodic_segments"]
    assert summary["segmentation_frame_accuracy"] >= 0.95


@pytest.mark.parametrize("command", sorted(set(COMMANDS) - {"credentials", "certificates", "bench"}))
def test_every_command_that_logs_takes_verbose(command, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0 and "-v, --verbose" in capsys.readouterr().out, command
