"""Messy generated takes (:mod:`lampskit.learn.synth_messy`): strokes that wander, pauses and slow strokes inside a
phase, hops that leave mid-stroke along a tilted normal and land inside the next patch, lift-offs, slides, noise
and dropped samples at 100-1000 Hz. Each family with its exact count of periodic MPs, and a property test over
random messy takes.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lampskit.learn.segmentation import segment
from lampskit.learn.segmentation_scores import frame_accuracy, segment_counts
from lampskit.learn.synth import PAD_LENGTH_M
from lampskit.learn.synth_messy import Move, PhaseSpec, draw_messy_take, messy_take

#: The issue's long phase: about 28 strokes of about 0.95 s whose centre drifts 5 cm, slowing a few times.
LONG = PhaseSpec((0.0, 0.0), "zigzag", 0.95, 0.06, 0.3, 28, drift_m=(0.05, 0.0), slow_strokes=3, pauses=2)


def _periodic(take) -> int:
    return segment_counts(segment(take.demo))["periodic"]


def test_the_generator_wanders_pauses_drops_and_lifts_as_asked():
    take = messy_take([LONG, PhaseSpec((0.126, 0.0), "circle", 1.0, 0.04)], [Move("hop", 0.065, 1.9, 0.3)], 0,
                      noise_m=0.0, drop_share=0.03)
    t, p = take.demo.t_s, take.demo.position_m
    board = (p - take.T_board_to_world[:3, 3]) @ take.T_board_to_world[:3, :3]
    dt = np.diff(t)
    assert np.sum(dt > 1.5e-2) > 0.005 * len(t), "samples dropped"
    (a0, b0), (a1, b1) = take.phases
    assert np.abs(board[a0:b0, 2]).max() < 0.002 and np.abs(board[a1:b1, 2]).max() < 0.002, "wiping on the board"
    assert board[b0:a1, 2].max() == pytest.approx(0.065 * np.cos(0.3), abs=0.003), "the hop's lift, tilted"
    speed = np.linalg.norm(np.diff(board[a0:b0], axis=0), axis=1) / dt[a0:b0 - 1]
    assert np.sum(speed < 0.01) * 0.01 > 0.9, "two pauses of 0.5 s inside the long phase"
    assert t[b0 - 1] - t[a0] > 28 * 0.95 * 0.8


@pytest.mark.parametrize("rate_hz", [100.0, 1000.0])
@pytest.mark.parametrize("seed", range(3))
def test_a_long_drifting_phase_with_pauses_and_slow_strokes_stays_one_periodic_mp(seed, rate_hz):
    take = messy_take([LONG], [], seed, rate_hz=rate_hz)
    seg = segment(take.demo)
    assert segment_counts(seg)["periodic"] == 1
    assert frame_accuracy(seg, take.true_periodic) >= 0.95


@pytest.mark.parametrize("seed", range(3))
def test_strokes_whose_period_and_amplitude_wander_stay_one_periodic_mp(seed):
    wild = PhaseSpec((0.0, 0.0), "circle", 1.1, 0.05, 0.0, 20, drift_m=(0.0, 0.03), period_jitter=0.2,
                     amp_jitter=0.2, slow_strokes=2)
    assert _periodic(messy_take([wild], [], seed, rate_hz=200.0)) == 1


@pytest.mark.parametrize("lift_m", [0.02, 0.05, 0.08])
@pytest.mark.parametrize("move_pads", [0.5, 1.0, 2.0])
def test_a_real_like_hop_cuts(lift_m, move_pads):
    """It leaves mid-stroke, lifts along a normal tilted 0.35 rad, lands on the next patch's first stroke; the
    strokes either side are not the same shape; both phases wander and pause."""
    a = PhaseSpec((0.0, 0.0), "circle", 1.0, 0.04, 0.0, 9, drift_m=(0.0, 0.01), pauses=1)
    b = PhaseSpec((move_pads * PAD_LENGTH_M, 0.0), "zigzag", 0.8, 0.05, 1.0, 10, slow_strokes=1)
    for seed in range(2):
        take = messy_take([a, b], [Move("hop", lift_m, 1.0 + move_pads * 0.5, 0.35)], seed)
        seg = segment(take.demo)
        assert segment_counts(seg)["periodic"] == 2, (seed, [(s.kind, s.start, s.end) for s in seg.segments])
        # the count is exact; the frames are not yet: the strokes after a pause or a slow stroke near a phase's
        # end recur for less than a period in time and are left transitional (docs/method.md, open points)
        assert frame_accuracy(seg, take.true_periodic) >= 0.7


def test_the_issues_hop_cuts():
    """Two wiping phases whose centres are 12.6 cm apart, joined by a 1.9 s move that lifts the pad 6.5 cm."""
    a = PhaseSpec((0.0, 0.0), "circle", 1.2, 0.05, 0.0, 10, pauses=1)
    b = PhaseSpec((0.126, 0.0), "circle", 1.1, 0.05, 2.0, 10, slow_strokes=1)
    for rate_hz in (100.0, 500.0):
        assert _periodic(messy_take([a, b], [Move("hop", 0.065, 1.9, 0.25)], 3, rate_hz=rate_hz)) == 2


def test_lift_offs_and_slides_to_far_spots_cut():
    phases = [PhaseSpec((0.0, 0.0), "zigzag", 1.0, 0.05, 0.5, 8, pauses=1),
              PhaseSpec((0.0, 0.05), "circle", 0.9, 0.04, 0.0, 8),
              PhaseSpec((0.25, 0.05), "zigzag", 1.2, 0.05, 2.0, 8, slow_strokes=1)]
    take = messy_take(phases, [Move("lift"), Move("slide")], 4, rate_hz=200.0)
    assert _periodic(take) == 3


@pytest.mark.parametrize("rate_hz", [100.0, 200.0, 500.0, 1000.0])
def test_noise_and_dropped_samples_at_every_rate(rate_hz):
    phases = [PhaseSpec((0.0, 0.0), "circle", 1.0, 0.045, 0.0, 10, drift_m=(0.02, 0.0), pauses=1),
              PhaseSpec((0.09, 0.03), "zigzag", 0.9, 0.05, 0.7, 10, slow_strokes=1)]
    take = messy_take(phases, [Move("hop", 0.03, 1.2, 0.4)], 5, rate_hz=rate_hz, noise_m=5e-4, drop_share=0.03)
    seg = segment(take.demo)
    assert segment_counts(seg)["periodic"] == 2
    assert frame_accuracy(seg, take.true_periodic) >= 0.9


@settings(derandomize=True, max_examples=12, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_every_random_messy_take_gets_its_exact_count(seed):
    take = draw_messy_take(seed, rate_hz=100.0 if seed % 2 else 200.0)
    assert _periodic(take) == take.n_periodic
