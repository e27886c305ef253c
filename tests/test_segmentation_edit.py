"""A user corrects a segmentation: ``lamps segment --json`` says how sure each cut is, ``lamps learn --segments``
learns from the file edited by hand (merge, split at a time, relabel) and refuses every bad edit by name."""

from __future__ import annotations

import json

import pytest

from lampskit.learn.segmentation import segment
from lampskit.learn.synth_messy import Move, PhaseSpec, messy_take
from runtime.cli import main


@pytest.fixture(scope="module")
def segmented(tmp_path_factory):
    folder = tmp_path_factory.mktemp("edit")
    demo = folder / "d.csv"
    assert main(["demo-data", "--stains", "3", "--seed", "0", "-o", str(demo)]) == 0
    assert main(["segment", str(demo), "--json", str(folder / "seg.json")]) == 0
    return demo, json.loads((folder / "seg.json").read_text())


def _learn(demo, segments, tmp_path, capsys) -> tuple[int, dict | None, str]:
    path = tmp_path / "edited.json"
    path.write_text(json.dumps({"segments": segments}))
    out = tmp_path / "skill.json"
    code = main(["learn", str(demo), "--segments", str(path), "-o", str(out)])
    err = capsys.readouterr().err
    return code, (json.loads(out.read_text()) if code == 0 else None), err


def test_every_cut_has_a_margin_and_its_evidence(segmented):
    _, data = segmented
    cuts = data["cuts"]
    assert len(cuts) == len(data["segments"]) - 1
    for cut, seg in zip(cuts, data["segments"][1:]):
        assert cut["sample"] == seg["start"] and cut["evidence"] in ("reachability", "continuity")
        assert isinstance(cut["margin"], float)
    between = [c for c in cuts if "lift" in c]
    assert between and all(c["margin"] > 0 for c in between), "cuts between two wipes are sure"


def test_a_hops_cut_is_sure_and_says_it_lifted():
    a = PhaseSpec((0.0, 0.0), "circle", 1.2, 0.05, 0.0, 10, pauses=1)
    b = PhaseSpec((0.126, 0.0), "circle", 1.1, 0.05, 2.0, 10, slow_strokes=1)
    seg = segment(messy_take([a, b], [Move("hop", 0.065, 1.9, 0.25)], 3).demo)
    inner = [c for c in seg.cuts if "lift" in c]
    assert len(inner) == 2 and all(c["lift"] > 1 and c["margin"] > 0.5 for c in inner)


def test_the_file_round_trips(segmented, tmp_path, capsys):
    demo, data = segmented
    code, skill, err = _learn(demo, data["segments"], tmp_path, capsys)
    assert code == 0, err
    assert skill["segmentation"]["segments"] == data["segments"]
    assert skill["segmentation"]["method"] == "edited"
    assert len(skill["periodic"]) == sum(s["kind"] == "periodic" for s in data["segments"]) == 3


def test_merge_split_at_a_time_and_relabel(segmented, tmp_path, capsys):
    demo, data = segmented
    segs = [dict(s) for s in data["segments"]]
    # relabel the last wipe transitional and merge it with its neighbours
    last = max(i for i, s in enumerate(segs) if s["kind"] == "periodic")
    merged = segs[:last - 1] + [{"start": segs[last - 1]["start"], "end": segs[-1]["end"], "kind": "transitional"}]
    code, skill, err = _learn(demo, merged, tmp_path, capsys)
    assert code == 0, err
    assert len(skill["periodic"]) == 2
    # split the first wipe in two at a time [s]
    from lampskit.learn.demo_io import read_demo

    t = read_demo(str(demo)).t_s
    first = next(i for i, s in enumerate(segs) if s["kind"] == "periodic")
    s0, s1 = segs[first]["start"], segs[first]["end"]
    mid = float(t[(s0 + s1) // 2] - t[0])
    timed = [{"start_s": float(t[s["start"]] - t[0]), "end_s": float(t[s["end"]] - t[0]) if s["end"] < len(t)
              else float(t[-1] - t[0]), "kind": s["kind"]} for s in segs]
    split = timed[:first] + [dict(timed[first], end_s=mid), dict(timed[first], start_s=mid)] + timed[first + 1:]
    code, skill, err = _learn(demo, split, tmp_path, capsys)
    assert code == 0, err
    assert len(skill["periodic"]) == 4


@pytest.mark.parametrize("edit, words", [
    (lambda s: s[:1] + [dict(s[1], start=s[1]["start"] - 5)] + s[2:], "overlap: segment 1"),
    (lambda s: s[:1] + [dict(s[1], start=s[1]["start"] + 5)] + s[2:], "gap between segments 0 and 1"),
    (lambda s: s[:-1] + [dict(s[-1], end=s[-1]["end"] + 10)], "out of range"),
    (lambda s: s[:-1] + [dict(s[-1], end=s[-1]["end"] - 10)], "gap after segment"),
    (lambda s: [{"start_s": 0.0, "end_s": 1e4, "kind": "periodic"}], "end_s=10000.0 is out of range"),
    (lambda s: [dict(x, kind="wiping") for x in s], "kind must be 'periodic' or 'transitional'"),
    (lambda s: [dict(x, kind="transitional") for x in s], "no periodic segment"),
    (lambda s: [{"kind": "periodic"}], "needs 'start' and 'end'"),
])
def test_bad_edits_are_refused_by_name(segmented, tmp_path, capsys, edit, words):
    demo, data = segmented
    code, _, err = _learn(demo, edit([dict(s) for s in data["segments"]]), tmp_path, capsys)
    assert code != 0 and words in err, err
    assert not (tmp_path / "skill.json").exists()


def test_segments_apply_to_one_demo_only(segmented, tmp_path, capsys):
    demo, data = segmented
    path = tmp_path / "s.json"
    path.write_text(json.dumps(data))
    code = main(["learn", str(demo), str(demo), "--segments", str(path), "-o", str(tmp_path / "k.json")])
    assert code != 0 and "one demonstration" in capsys.readouterr().err


def test_plot_writes_the_figure_and_an_mcap_with_the_segments(segmented, tmp_path, capsys):
    from mcap.reader import make_reader

    from lampskit.learn.segment_plot import SEGMENTS_TOPIC, TAKE_TOPIC

    from .mcap_check import check_recording

    demo, data = segmented
    assert main(["segment", str(demo), "--plot", str(tmp_path / "seg")]) == 0
    png, mcap = tmp_path / "seg.png", tmp_path / "seg.mcap"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    topics = check_recording(mcap, every=1)
    assert topics[SEGMENTS_TOPIC] == ("lamps.Segment", len(data["segments"]))
    assert topics[TAKE_TOPIC][1] > 1000
    with open(mcap, "rb") as f:
        kinds = [json.loads(m.data)["kind"] for _, c, m in make_reader(f).iter_messages(topics=[SEGMENTS_TOPIC])]
    assert kinds == [s["kind"] for s in data["segments"]]
