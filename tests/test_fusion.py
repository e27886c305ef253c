"""One skill from several demonstrations: MPs fused by GMM-GMR over all of them, their spread recorded."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lampskit.core.skill import load_skill
from lampskit.errors import LearningError
from lampskit.learn.demo import Demonstration
from lampskit.learn.demo_io import write_demo_csv
from lampskit.learn.fusion import fuse_periodic, fuse_transitional
from lampskit.learn.learn import learn_skill_from_demos
from lampskit.learn.periodic_fit import learn_periodic
from lampskit.learn.synth import synthesize_demo

RATE = 150.0


def _circle(t: np.ndarray, phase0: float = 0.0, centre=(0.3, 0.2), r: float = 0.04) -> np.ndarray:
    """A 1.5 Hz ellipse-ish stroke (T, 2) [m] with a second harmonic, so its shape has a phase to align."""
    w = 2 * np.pi * 1.5 * t + phase0
    return np.column_stack([centre[0] + r * np.cos(w) + 0.2 * r * np.cos(2 * w), centre[1] + 0.7 * r * np.sin(w)])


def _template_error(mp, truth_at) -> float:
    """RMS distance [m] from the MP's template to the true stroke, best over the true stroke's phase."""
    grid = np.linspace(0, 2 * np.pi, 512, endpoint=False)
    best = np.inf
    for shift in grid[::2]:
        true = truth_at(grid + shift)
        best = min(best, float(np.sqrt(np.mean(np.sum((mp.template_m - true) ** 2, axis=1)))))
    return best


def test_fusing_noisy_repeats_of_a_stroke_recovers_it_better_than_one_and_reports_their_spread():
    rng = np.random.default_rng(0)
    t = np.arange(0, 4.0, 1 / RATE)
    noise = 0.004
    # three demonstrations: different start phases (the segmentation cut anywhere), centres 5 mm apart, noise
    segs = [(t, _circle(t, phase0=p, centre=(0.3 + dx, 0.2)) + rng.normal(0, noise, (len(t), 2)))
            for p, dx in ((0.0, 0.0), (1.9, 0.005), (4.0, -0.005))]
    fused, spread = fuse_periodic(segs)
    one = learn_periodic(*segs[0])

    def truth(phi):
        return _circle(phi / (2 * np.pi * 1.5), centre=(0.3, 0.2))

    e_fused, e_one = _template_error(fused, truth), _template_error(one, truth)
    assert e_fused < 0.8 * e_one, (e_fused, e_one)
    assert fused.omega_rad_s == pytest.approx(2 * np.pi * 1.5, rel=0.01)
    assert spread["n_demos"] == 3 and spread["centre_std_m"] == pytest.approx(np.sqrt(2 / 3) * 0.005, rel=0.2)
    assert spread["path_rms_m"] < 0.003 and spread["freq_std_hz"] < 0.02, spread
    # the start phases were aligned: without that the spread would be the stroke's own size
    assert spread["path_max_std_m"] < 0.004


def test_fusing_transitions_averages_the_move_from_each_start_and_its_duration():
    t1, t2 = np.linspace(0, 1.0, 151), np.linspace(0, 1.4, 211)
    s1, s2 = t1 / t1[-1], t2 / t2[-1]
    ease = lambda s: 10 * s**3 - 15 * s**4 + 6 * s**5  # noqa: E731
    bump = lambda s: 64 * s**3 * (1 - s) ** 3  # noqa: E731
    a = np.column_stack([0.2 * ease(s1), 0.02 * bump(s1)])
    b = np.column_stack([0.2 * ease(s2), -0.02 * bump(s2)]) + [0.01, 0.0]  # bulges the other way, 1 cm over
    mp, spread = fuse_transitional([(t1, a), (t2, b)])
    assert mp.demo_duration_s == pytest.approx(1.2)
    assert mp.demo_start[0] == pytest.approx([0.005, 0.0], abs=2e-4)
    assert np.linalg.norm(mp.demo_displacement_m - [0.2, 0.0]) < 0.003
    assert spread["path_max_std_m"] == pytest.approx(0.02, rel=0.1) and spread["duration_std_s"] == pytest.approx(0.2)
    assert spread["start_std_m"] == pytest.approx(0.005)


def _copies(n: int) -> list[Demonstration]:
    base = synthesize_demo(3, 0).demo
    rng = np.random.default_rng(5)
    return [Demonstration(base.t_s, base.position_m + rng.normal(0, 0.0008, base.position_m.shape)
                          + rng.normal(0, 0.003, 3), base.orientation_wxyz, source=f"take {k}") for k in range(n)]


def test_a_skill_from_three_demonstrations_fuses_every_mp_and_records_the_spread():
    demos = _copies(3)
    skill, segs = learn_skill_from_demos(demos)
    assert len(segs) == 3 and len(skill.periodic) == 3 and len(skill.transitional) == 4
    assert [d["demo"] for d in skill.source["demos"]] == ["take 0", "take 1", "take 2"]
    for sp in skill.source["spread"]["periodic"]:
        assert sp["n_demos"] == 3 and sp["path_rms_m"] < 0.002 and 0.002 < sp["centre_std_m"] < 0.01, sp
    for sp in skill.source["spread"]["transitional"]:
        assert sp["n_demos"] == 3 and sp["path_rms_m"] < 0.01, sp


def test_demonstrations_with_different_phases_are_refused_naming_them():
    four = synthesize_demo(4, 1).demo
    with pytest.raises(LearningError, match=r"same number of wiping phases.*take 0: 3.*synthetic\(n_stains=4"):
        learn_skill_from_demos(_copies(1) + [four])


def test_lamps_learn_takes_several_demonstrations(tmp_path):
    paths = [write_demo_csv(tmp_path / f"take{k}.csv", d) for k, d in enumerate(_copies(2))]
    out = tmp_path / "skill.json"
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "learn", *map(str, paths), "-o", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "fused from 2 demonstrations" in r.stdout and "spread" in r.stdout
    skill = load_skill(out)
    assert len(skill.source["demos"]) == 2 and len(skill.source["spread"]["periodic"]) == 3
    assert json.loads(out.read_text())["source"]["spread"]["transitional"][0]["n_demos"] == 2
    bad = subprocess.run([sys.executable, "-m", "runtime.cli", "learn", str(paths[0]), str(tmp_path / "nope.csv"),
                          "-o", str(tmp_path / "x.json")], capture_output=True, text=True, timeout=300)
    assert bad.returncode != 0 and "nope.csv" in bad.stderr and not (tmp_path / "x.json").exists()
