"""The paper's Figs. 6-7 show a transition as it was demonstrated, on synthetic and on real demonstrations."""

from __future__ import annotations

from pathlib import Path

import pytest

from lampskit.figures.primitives import figure_transition_comparison, figure_transition_phases, shown_transition
from lampskit.learn.demo_io import read_demo
from lampskit.learn.learn import learn_skill

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "wiping-demos" / "circular_wiping_dataset.mat"


def test_a_transition_between_two_stains_is_shown_between_them(learned_skill):
    shown = shown_transition(learned_skill)
    assert shown.before is not None and shown.after is not None
    assert shown.tr.segment - 1 == shown.before.segment and shown.tr.segment + 1 == shown.after.segment


@pytest.mark.skipif(not REAL.is_file(), reason="the real wiping demos are not beside the repo")
def test_a_real_single_wipe_shows_its_demonstrated_approach_at_its_own_duration(tmp_path):
    """A single-wipe recording has no transition between stains: the approach is the one demonstrated, at its own
    duration, not squeezed between two phases of the one stroke."""
    demo = read_demo(f"{REAL}#0")
    skill, seg = learn_skill(demo)
    shown = shown_transition(skill)
    assert shown.before is None and shown.after is not None and "demonstrated approach" in shown.note
    assert shown.T == pytest.approx(shown.tr.mp.demo_duration_s) and shown.T > 2.0
    s = seg.segments[shown.tr.segment]
    assert shown.T == pytest.approx(demo.t_s[s.end - 1] - demo.t_s[s.start], rel=0.05)
    for path in (figure_transition_comparison(demo, skill, seg, tmp_path / "fig6.png"),
                 figure_transition_phases(skill, tmp_path / "fig7.png")):
        assert path.stat().st_size > 10_000
