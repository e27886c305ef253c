"""Synthetic takes that do what people do (lift-offs, revisits, pauses, grip shifts) and their segmentation.

The generator's behaviours are checked on the noise-free signal against the truth it returns; then every seed of
2-8 stains is segmented with the automatic threshold: every wiping phase found as its own periodic segment.
"""

from __future__ import annotations

import numpy as np
import pytest

from lampskit.learn.segmentation import segment
from lampskit.learn.segmentation_scores import frame_accuracy, segment_counts, true_segment_count
from lampskit.learn.synth import synthesize_demo
from lampskit.learn.synth_human import LIFT_HEIGHT_M, PAUSE_S, HumanPlan


def _board(s) -> np.ndarray:
    """Positions in the board frame (T, 3) [m]: z is the height off the board."""
    T = s.T_board_to_world
    return (s.demo.position_m - T[:3, 3]) @ T[:3, :3]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return list(zip(edges[::2], edges[1::2]))


def test_plain_demos_are_what_they_were():
    """The bundled skill is learned from these: the human behaviours come from a second stream and leave them."""
    s = synthesize_demo(3, 0)
    assert s.demo.n_samples == 2720 and s.segments[:3] == ((0, 266, "transitional", -1), (266, 749, "periodic", 0),
                                                           (749, 1290, "transitional", -1))


@pytest.mark.parametrize("n_stains, seed", [(1, 0), (3, 1), (5, 2), (8, 3)])
def test_a_human_take_lifts_off_revisits_pauses_and_shifts_its_grip(n_stains, seed):
    s = synthesize_demo(n_stains, seed, rate_hz=1000.0, noise_m=0.0, human=True)
    plan = HumanPlan.draw(list(range(n_stains)), np.random.default_rng([seed, 1]))
    p, t, per = _board(s), s.demo.t_s, s.true_periodic
    wipes = [(a, b, st) for a, b, k, st in s.segments if k == "periodic"]
    assert len(wipes) == n_stains + 1 == true_segment_count(per)
    stains = [st for *_, st in wipes]
    assert sorted(set(stains)) == list(range(n_stains)) and len(stains) - len(set(stains)) == 1, "one revisit"
    r = next(i for i in range(len(stains) - 1) if stains[i] == stains[i + 1])
    between = p[wipes[r][1]:wipes[r + 1][0]]
    assert LIFT_HEIGHT_M[0] - 0.005 < between[:, 2].max() < LIFT_HEIGHT_M[1] + 0.005, "lifted off, then back"
    assert np.all(np.abs(p[per, 2]) < 1e-9), "wiping is on the board"
    # a real retract is fastest early: the height's speed peaks well before the top (a symmetric rise: at 0.59)
    tb = t[wipes[r][1]:wipes[r + 1][0]] - t[wipes[r][1]]
    z = between[:, 2]
    top = int(np.argmax(z >= 0.99 * z.max()))
    t_fastest = tb[int(np.argmax(np.diff(z[:top + 1]) / np.diff(tb[:top + 1])))]
    assert t_fastest < 0.5 * tb[top], (t_fastest, tb[top])
    # the pause: the tool stands still, labelled transitional
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(t)
    still = [(a, b) for a, b in _runs(speed < 1e-9) if t[b] - t[a] > 0.5]
    assert len(still) >= 1 and all(not per[a:b].any() for a, b in still)
    assert PAUSE_S[0] - 0.01 <= max(t[b] - t[a] for a, b in still) <= PAUSE_S[1] + 0.01
    # the grip shift: the shifted wipe's centre moves 1.5-3 cm between its first and last periods
    a, b, _ = wipes[plan.shift_piece]
    n = (b - a) // 4
    moved = np.linalg.norm(p[b - n:b, :2].mean(axis=0) - p[a:a + n, :2].mean(axis=0))
    assert 0.008 < moved < 0.045, moved
    # C2: no jump in acceleration anywhere (junctions included): bounded like a hand's
    v = np.diff(p, axis=0) / np.diff(t)[:, None]
    acc = np.diff(v, axis=0) / np.diff(t)[1:, None]
    assert np.abs(acc).max() < 40.0


@pytest.mark.parametrize("n_stains", range(2, 9))
@pytest.mark.parametrize("seed", range(5))
def test_every_wiping_phase_of_a_human_take_is_found(n_stains, seed):
    s = synthesize_demo(n_stains, seed, human=True)
    seg = segment(s.demo)
    assert segment_counts(seg)["periodic"] == true_segment_count(s.true_periodic) == n_stains + 1
    assert frame_accuracy(seg, s.true_periodic) >= 0.9
    stains = [st for *_, k, st in s.segments if k == "periodic"]
    clusters = [x.cluster for x in seg.periodic_segments]
    r = next(i for i in range(len(stains) - 1) if stains[i] == stains[i + 1])
    assert clusters[r] == clusters[r + 1], "the spot wiped again after a lift-off is the same cluster"
