"""Segmentation (paper II-A): synthetic demos with truth, invariants, baselines, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.cluster import cluster_optics_dbscan

from lampskit.errors import SegmentationError
from lampskit.learn.demo import Demonstration
from lampskit.learn.reachability import dbscan_labels, otsu_threshold
from lampskit.learn.segmentation import PROGRESS_TOTAL, Segment, Segmentation, segment
from lampskit.learn.segmentation_scores import frame_accuracy, segment_counts, true_segment_count
from lampskit.learn.synth import synthesize_demo


def _check_invariants(seg: Segmentation, n: int) -> None:
    """Segments tile [0, n) in order; labels agree; kinds alternate sensibly."""
    assert seg.segments[0].start == 0 and seg.segments[-1].end == n
    for a, b in zip(seg.segments, seg.segments[1:]):
        assert a.end == b.start
        assert not (a.kind == b.kind == "transitional")
        assert not (a.kind == b.kind == "periodic" and a.cluster == b.cluster)
    assert seg.labels.shape == (n,)
    for s in seg.segments:
        assert np.all(seg.labels[s.start : s.end] == s.cluster)
    assert sorted({s.cluster for s in seg.periodic_segments}) == list(range(segment_counts(seg)["clusters"]))


@pytest.mark.parametrize("n_stains", [2, 3, 4, 5, 6])
@pytest.mark.parametrize("seed", range(5))
def test_synthetic_demos_are_segmented(n_stains, seed):
    s = synthesize_demo(n_stains, seed)
    seg = segment(s.demo)
    _check_invariants(seg, s.demo.n_samples)
    assert segment_counts(seg)["periodic"] == n_stains == true_segment_count(s.true_periodic)
    assert frame_accuracy(seg, s.true_periodic) >= 0.95
    # each periodic segment lies on its own stain
    for found, (a, b, _kind, _stain) in zip(seg.periodic_segments, [x for x in s.segments if x[2] == "periodic"]):
        assert found.start < b and a < found.end
    assert len({x.cluster for x in seg.periodic_segments}) == n_stains


@pytest.mark.parametrize("rate_hz", [100.0, 200.0])
def test_default_min_samples_follows_the_rate(rate_hz):
    s = synthesize_demo(3, 7, rate_hz=rate_hz)
    seg = segment(s.demo)
    assert seg.min_samples == round(0.5 * s.demo.rate_hz)
    assert segment_counts(seg)["periodic"] == 3
    assert frame_accuracy(seg, s.true_periodic) >= 0.95


@pytest.mark.parametrize("rate_hz", [400.0, 1000.0, 2000.0])
def test_fast_recordings_are_thinned_to_the_same_point_density(rate_hz):
    """Above 200 Hz the kept points are no denser than at 200 Hz: same answer, OPTICS cost bounded."""
    s = synthesize_demo(3, 7, rate_hz=rate_hz)
    ref = segment(synthesize_demo(3, 7, rate_hz=200.0).demo)
    seg = segment(s.demo)
    assert seg.min_samples == 100 == ref.min_samples
    # kept spacing is step plus up to one raw sample: a little denser at high rates
    assert len(seg.point_samples) == pytest.approx(len(ref.point_samples), rel=0.25)
    assert segment_counts(seg)["periodic"] == 3
    assert frame_accuracy(seg, s.true_periodic) >= 0.95
    # the boundaries (refined on every q-th sample, q = ceil(rate / 200)) land where the 200 Hz recording's do
    ref_demo = synthesize_demo(3, 7, rate_hz=200.0).demo

    def ends(x, demo):
        return [demo.t_s[p.start] for p in x.periodic_segments] + [demo.t_s[p.end - 1] for p in x.periodic_segments]

    assert np.max(np.abs(np.subtract(ends(seg, s.demo), ends(ref, ref_demo)))) < 0.05


def test_same_region_wiped_twice_gives_two_segments_of_one_cluster():
    s = synthesize_demo(3, 2, revisit_first=True)
    seg = segment(s.demo)
    per = seg.periodic_segments
    assert len(per) == 4 and segment_counts(seg)["clusters"] == 3
    assert per[0].cluster == per[-1].cluster == 0
    assert frame_accuracy(seg, s.true_periodic) >= 0.95


def _line_demo(kind: str) -> Demonstration:
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 6.0, 1 / 150)
    s = t / t[-1]
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    zero = 0 * t
    paths = {
        "straight line": np.c_[0.5 * s, zero, zero],
        "single sweep": np.c_[0.4 * np.cos(np.pi * s), 0.4 * np.sin(np.pi * s), zero],
        "there and back": np.c_[0.3 * np.sin(np.pi * s), zero, zero],
        "resting tool": np.c_[zero, zero, zero],
    }
    return Demonstration(t, paths[kind] + rng.normal(scale=4e-4, size=(len(t), 3)), source=kind)


@pytest.mark.parametrize(
    ("kind", "why"),
    [
        ("straight line", "passed over densely enough"),
        ("single sweep", "passed over densely enough"),
        ("there and back", r"path length / extent [0-9.]+ < 3"),
        ("resting tool", r"extent .* mm < 5 mm"),
    ],
)
def test_demo_without_periodic_part_raises(kind, why):
    with pytest.raises(SegmentationError, match=rf"{kind}: no periodic part found .*{why}"):
        segment(_line_demo(kind))


def test_motionless_demo_raises():
    demo = Demonstration(np.arange(200) * 0.01, np.ones((200, 3)), source="still")
    with pytest.raises(SegmentationError, match="still: the tool does not move"):
        segment(demo)


def test_to_dict_is_json_and_complete():
    s = synthesize_demo(2, 3)
    seg = segment(s.demo)
    d = json.loads(json.dumps(seg.to_dict()))
    assert d["method"] == "optics" and d["threshold"] == pytest.approx(seg.threshold)
    assert d["segments"] == [x.to_dict() for x in seg.segments]
    assert len(d["ordering"]) == len(d["reachability"]) == len(seg.point_samples)
    assert d["reachability"][0] is None and all(r > 0 for r in d["reachability"][1:])
    np.testing.assert_array_equal(d["ordering"], seg.point_samples[seg.optics.ordering])
    assert set(seg.to_dict(summary=True)) == {"method", "threshold", "min_samples", "step_m", "n_samples", "segments"}
    assert seg.ordering_labels.shape == seg.reachability_plot.shape


def test_threshold_and_min_samples_can_be_given():
    s = synthesize_demo(2, 4)
    auto = segment(s.demo)
    seg = segment(s.demo, threshold=0.8 * auto.threshold, min_samples=auto.min_samples + 10)
    assert seg.threshold == pytest.approx(0.8 * auto.threshold)
    assert seg.min_samples == auto.min_samples + 10
    assert segment_counts(seg)["periodic"] == 2


def test_progress_reaches_the_end():
    calls = []
    segment(synthesize_demo(2, 0).demo, progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (PROGRESS_TOTAL, PROGRESS_TOTAL) and len(calls) > 5
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


@pytest.mark.parametrize("method", ["kmeans", "affinity"])
def test_baselines_label_everything_periodic(method):
    s = synthesize_demo(3, 1)
    seg = segment(s.demo, method=method)
    _check_invariants(seg, s.demo.n_samples)
    assert seg.method == method and seg.threshold is None and seg.optics is None
    assert all(x.kind == "periodic" for x in seg.segments)  # no notion of transitional points
    assert frame_accuracy(seg, s.true_periodic) == pytest.approx(s.true_periodic.mean())
    d = json.loads(json.dumps(seg.to_dict()))
    assert d["ordering"] == [] and d["reachability"] == []


def test_the_fixed_threshold_baseline_is_sklearn_optics_read_at_that_threshold():
    """Plain scikit-learn OPTICS at a fixed 40 mm (the bundled demo's automatic threshold): right where it was
    read, wrong on a denser or sparser demo; its noise points are transitional."""
    s = synthesize_demo(3, 1)
    seg = segment(s.demo, method="sklearn-optics")
    _check_invariants(seg, s.demo.n_samples)
    assert seg.method == "sklearn-optics" and seg.threshold == 0.04 and seg.optics is None
    assert any(x.kind == "transitional" for x in seg.segments)
    assert np.array_equal(seg.point_samples, segment(s.demo).point_samples), "the same points as ours"
    tight = segment(s.demo, method="sklearn-optics", threshold=0.005)
    assert segment_counts(tight)["periodic"] != segment_counts(seg)["periodic"] or \
        frame_accuracy(tight, s.true_periodic) < frame_accuracy(seg, s.true_periodic)


def test_kmeans_with_given_k():
    demo = synthesize_demo(2, 1).demo
    few, many = (segment_counts(segment(demo, method="kmeans", n_clusters=k)) for k in (2, 6))
    assert few["clusters"] == 2 and few["periodic"] == 2
    assert many["clusters"] > 2 and many["periodic"] > few["periodic"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "dbscan"}, "unknown segmentation method 'dbscan'; valid: optics, kmeans, affinity, sklearn-optics"),
        ({"min_samples": 1}, "min_samples must be an int >= 2"),
        ({"min_samples": 5.0}, "min_samples must be an int >= 2"),
        ({"threshold": -0.01}, "threshold must be a finite reachability > 0 m"),
        ({"threshold": float("nan")}, "threshold must be a finite reachability > 0 m"),
        ({"min_duration_s": -1.0}, "min_duration_s must be a finite duration >= 0 s"),
        ({"min_path_ratio": 0.5}, "min_path_ratio must be finite and >= 1"),
        ({"n_clusters": 1}, "n_clusters must be an int >= 2"),
    ],
)
def test_bad_parameters_are_rejected(kwargs, match):
    demo = _line_demo("straight line")
    with pytest.raises(SegmentationError, match=match):
        segment(demo, **kwargs)


def test_frame_accuracy_and_counts():
    labels = np.array([-1] * 4 + [0] * 6 + [-1] * 2 + [1] * 3)
    segs = (Segment(0, 4, "transitional", -1), Segment(4, 10, "periodic", 0),
            Segment(10, 12, "transitional", -1), Segment(12, 15, "periodic", 1))
    seg = Segmentation(segs, labels, "optics", 0.01, 5, 0.001, np.arange(15), None)
    truth = labels >= 0
    assert frame_accuracy(seg, truth) == 1.0
    truth[:3] = True
    assert frame_accuracy(seg, truth) == pytest.approx(12 / 15)
    assert segment_counts(seg) == {"periodic": 2, "transitional": 2, "clusters": 2}
    assert true_segment_count(labels >= 0) == 2
    with pytest.raises(SegmentationError, match=r"true_periodic must have shape \(15,\)"):
        frame_accuracy(seg, truth[:-1])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"start": 3, "end": 3, "kind": "periodic", "cluster": 0}, r"0 <= start < end"),
        ({"start": 0, "end": 3, "kind": "wipe", "cluster": 0}, "kind must be 'periodic' or 'transitional'"),
        ({"start": 0, "end": 3, "kind": "periodic", "cluster": -1}, "periodic segment needs cluster >= 0"),
        ({"start": 0, "end": 3, "kind": "transitional", "cluster": 2}, "transitional segment needs cluster -1"),
    ],
)
def test_segment_validation(kwargs, match):
    with pytest.raises(SegmentationError, match=match):
        Segment(**kwargs)


def test_otsu_splits_two_modes():
    rng = np.random.default_rng(0)
    values = np.r_[rng.normal(0.0, 0.1, 300), rng.normal(3.0, 0.1, 100)]
    assert 0.5 < otsu_threshold(values) < 2.5
    with pytest.raises(SegmentationError, match="two distinct values"):
        otsu_threshold(np.ones(4))


def test_dbscan_labels_match_sklearn():
    s = synthesize_demo(3, 5)
    seg = segment(s.demo)
    r = seg.optics
    for eps in (0.5 * seg.threshold, seg.threshold, 2 * seg.threshold):
        ref = cluster_optics_dbscan(
            reachability=np.array(r.reachability), core_distances=np.array(r.core_distances),
            ordering=np.array(r.ordering), eps=eps,
        )
        np.testing.assert_array_equal(dbscan_labels(r, eps), ref)


def test_clusters_taking_turns_within_one_stroke_are_united_but_separate_wipes_are_not():
    from lampskit.learn.time_runs import unite_alternating

    t = np.arange(3000) * 0.01
    # one stroke falling apart into clusters 0 and 1 every half cycle (0.8 s), short gaps between them
    turns = [(-1, 0, 200), (0, 200, 280), (-1, 280, 285), (1, 285, 365), (0, 365, 445), (1, 445, 525),
             (-1, 525, 1000), (2, 1000, 1600), (-1, 1600, 2000), (0, 2000, 2600), (-1, 2600, 3000)]
    out = unite_alternating(turns, t, 0.3)
    assert out[:5] == [(-1, 0, 200), (0, 200, 280), (-1, 280, 285), (0, 285, 525), (-1, 525, 1000)], out
    assert (2, 1000, 1600) in out and (0, 2000, 2600) in out, "wipes apart in time stay apart"
    # a wipe of 0, a short slide to a whole wipe of 2 and back to 0: a real visit, not a half cycle
    visit = [(0, 0, 600), (-1, 600, 610), (2, 610, 1200), (-1, 1200, 1210), (0, 1210, 1800)]
    assert unite_alternating(visit, t, 0.3) == visit


def test_fig4_colours_each_bar_by_the_label_of_the_point_at_that_position_of_the_ordering():
    """The bars used to take the label of *sample* number k (most bars got another point's colour): a valley below
    the threshold is a cluster's points, and they must be drawn in that cluster's colour."""
    from lampskit.figures.demo import reachability_bars

    s = synthesize_demo(3, 5)
    seg = segment(s.demo)
    heights, labels = reachability_bars(seg)
    assert len(heights) == len(labels) == len(seg.point_samples) and np.all(np.isfinite(heights))
    assert np.array_equal(labels, seg.labels[seg.point_samples[seg.optics.ordering]])
    valley = heights < seg.threshold
    assert np.mean(labels[valley] >= 0) > 0.8, "valley bars are periodic points (the spiral-in ends are not)"
    wrong = seg.labels[seg.optics.ordering]  # the old indexing, for contrast
    assert np.mean(wrong[valley] >= 0) < np.mean(labels[valley] >= 0) - 0.1


def _touch_down_then_strokes(arrive: str) -> tuple[np.ndarray, np.ndarray, int]:
    """A tool reaching a board (z = 0), then circles of 5 cm at 0.2 m/s: positions (K, 3) [m], speeds (K,) [m/s]
    at 100 Hz, and the index where the circles start. ``arrive``: "press" comes down along the normal and
    presses for 0.6 s at 2 cm/s before the first stroke (as in real demo 0); "slide" arrives along the board at
    stroke speed."""
    rate = 100.0
    w = 0.2 / 0.05
    t = np.arange(int(6 * 2 * np.pi / w * rate)) / rate
    circles = np.c_[0.05 * np.cos(w * t), 0.05 * np.sin(w * t), np.zeros_like(t)]
    start = circles[0]
    if arrive == "press":
        press = start + np.c_[np.zeros(60), -np.linspace(0.012, 0.0, 60), np.zeros(60)]
        down = start + press[0] - start + np.c_[np.zeros(40), np.zeros(40), np.linspace(0.08, 0.001, 40)]
        lead = np.vstack([down, press])
    else:
        lead = start + np.c_[np.linspace(-0.3, -0.002, 80), np.zeros(80), np.zeros(80)]
    points = np.vstack([lead, circles])
    speed = np.r_[np.linalg.norm(np.diff(points, axis=0), axis=1) * rate, 0.2]
    return points, speed, len(lead)


def test_a_wipe_starts_where_the_tool_settles_on_the_surface_not_where_a_slide_enters_it():
    from lampskit.learn.time_runs import settle_start

    points, speed, first_stroke = _touch_down_then_strokes("press")
    start = settle_start(points, speed, first_stroke, len(points), 0)
    # the 60 pressing samples are the wipe's, the descent at 0.2 m/s is not
    assert start == first_stroke - 60, start
    # never before the previous wiping phase
    assert settle_start(points, speed, first_stroke, len(points), first_stroke - 20) == first_stroke - 20
    points, speed, first_stroke = _touch_down_then_strokes("slide")
    assert settle_start(points, speed, first_stroke, len(points), 0) == first_stroke
