"""Short hops between nearby wipes (a person lifts the pad briefly and moves it on): each wiping phase is its
own periodic MP however close the patches are, while one wipe whose stroke centre drifts stays one MP.

Synthetic demos over the grid of lifts {2, 5, 8} cm, moves {0.5, 1, 2} pad lengths and durations {1, 3} s;
taught takes (the real recordings joined by such hops, skipped without ../shared/data) over its corners.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lampskit.learn.learn import MIN_TRANSITION_S
from lampskit.learn.lifts import heights, split_at_lifts
from lampskit.learn.reachability import smooth_positions
from lampskit.learn.segmentation import segment
from lampskit.learn.segmentation_scores import frame_accuracy, segment_counts
from lampskit.learn.synth import PAD_LENGTH_M, HopSpec, synthesize_demo
from lampskit.learn.takes import Piece, TakeRecipe, build_take

from .conftest import REAL_DEMOS

GRID = list(itertools.product((0.02, 0.05, 0.08), (0.5, 1.0, 2.0), (1.0, 3.0)))
CORNERS = list(itertools.product((0.02, 0.08), (0.5, 2.0), (1.0, 3.0)))


def _board_z(s) -> np.ndarray:
    T = s.T_board_to_world
    return ((s.demo.position_m - T[:3, 3]) @ T[:3, :3])[:, 2]


def _check_hops_between_wipes(seg, t_s: np.ndarray, n_wipes: int) -> None:
    """Exactly ``n_wipes`` periodic MPs, each pair joined by one transitional MP long enough to be learned."""
    kinds = [s.kind for s in seg.segments]
    first = kinds.index("periodic")
    inner = seg.segments[first: len(kinds) - kinds[::-1].index("periodic")]
    assert [s.kind for s in inner] == ["periodic", "transitional"] * (n_wipes - 1) + ["periodic"]
    for s in inner[1::2]:
        assert t_s[s.end - 1] - t_s[s.start] >= MIN_TRANSITION_S


def test_a_hop_lifts_moves_and_lasts_as_asked():
    hop = HopSpec(0.05, 1.0, 2.0)
    s = synthesize_demo(3, 0, noise_m=0.0, hop=hop)
    z, t = _board_z(s), s.demo.t_s
    for (a, b, kind, _), _nxt in zip(s.segments[1:-1], s.segments[2:]):
        if kind == "transitional":
            assert t[b - 1] - t[a] == pytest.approx(hop.duration_s, abs=0.02)
            assert z[a:b].max() == pytest.approx(hop.lift_m, abs=0.002)
    centres = [s.strokes[k].centre_m for k in range(3)]
    for c0, c1 in zip(centres, centres[1:]):
        assert np.linalg.norm(c1 - c0) == pytest.approx(hop.move_pads * PAD_LENGTH_M)
    from arm.description import PAD_SIZE_M

    assert PAD_LENGTH_M == PAD_SIZE_M[0]
    plain = synthesize_demo(3, 0, noise_m=0.0)
    assert [st.kind for st in plain.strokes] == [st.kind for st in s.strokes]  # the same strokes, re-placed


@pytest.mark.parametrize("lift_m, move_pads, duration_s", GRID)
def test_every_wipe_between_hops_is_its_own_periodic_mp(lift_m, move_pads, duration_s):
    s = synthesize_demo(3, 0, hop=HopSpec(lift_m, move_pads, duration_s))
    seg = segment(s.demo)
    assert segment_counts(seg)["periodic"] == 3
    _check_hops_between_wipes(seg, s.demo.t_s, 3)
    assert frame_accuracy(seg, s.true_periodic) >= 0.9


@pytest.mark.parametrize("drift_m", [0.03, 0.06])
@pytest.mark.parametrize("seed", range(3))
def test_a_wipe_whose_stroke_centre_drifts_stays_one_periodic_mp(drift_m, seed):
    s = synthesize_demo(3, seed, drift_m=drift_m)
    seg = segment(s.demo)
    assert segment_counts(seg)["periodic"] == 3
    assert frame_accuracy(seg, s.true_periodic) >= 0.9


def test_a_drift_in_contact_is_never_cut_but_a_hop_is():
    """The lift rule alone: a drifting wipe never leaves its surface; a hop's lift is cut out as transitional."""
    for kwargs, cuts in ((dict(drift_m=0.06), 0), (dict(hop=HopSpec(0.02, 0.5, 1.0)), 2)):
        s = synthesize_demo(3, 1, **kwargs)
        smooth = smooth_positions(s.demo.position_m, s.demo.rate_hz)
        n = s.demo.n_samples
        a, b = s.segments[1][0], s.segments[-2][1]  # every wipe and whatever lies between them as one run
        runs = split_at_lifts([(-1, 0, a), (0, a, b), (-1, b, n)], smooth, s.demo.rate_hz)
        assert sum(c == -1 for c, _, _ in runs) - 2 == cuts
        h = heights(smooth[a:b], smooth_positions(smooth, s.demo.rate_hz, deriv=1)[a:b], smooth)
        # the surface found is the board (within the 5 mm band floor)
        assert np.percentile(np.abs(h - _board_z(s)[a:b]), 99) < 0.004


@pytest.fixture(scope="module")
def recordings():
    if not REAL_DEMOS.is_file():
        pytest.skip(f"real data absent: {REAL_DEMOS}")
    from lampskit.learn.demo_io import read_demo, read_labels

    demos = [read_demo(f"{REAL_DEMOS}#{i}") for i in range(4)]
    return demos, [read_labels(f"{REAL_DEMOS}#{i}", d.n_samples) for i, d in enumerate(demos)]


@pytest.mark.realdata
@pytest.mark.parametrize("lift_m, move_pads, duration_s", CORNERS)
def test_taught_wipes_joined_by_a_hop_are_two_periodic_mps(recordings, lift_m, move_pads, duration_s):
    demos, labels = recordings
    for first in range(4):
        second = (first + 1) % 4
        recipe = TakeRecipe("hop", (Piece(first, (0.0, 0.0)),
                                    Piece(second, (move_pads * PAD_LENGTH_M, 0.0), hop_before=(lift_m, duration_s))))
        take = build_take(recipe, demos, labels)
        seg = segment(take.demo)
        assert segment_counts(seg)["periodic"] == 2, (first, second)
        _check_hops_between_wipes(seg, take.demo.t_s, 2)
        assert frame_accuracy(seg, take.true_periodic) >= 0.85, (first, second)
