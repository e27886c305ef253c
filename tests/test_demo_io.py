"""Demonstration readers and writers: round trips, the QTM rigid-body fit, and every kind of bad input."""

from __future__ import annotations

import numpy as np
import pytest

from interfaces.transforms import matrix_from_quat_wxyz, quat_wxyz_from_matrix
from lampskit.errors import DemoError
from lampskit.learn import demo_io
from lampskit.learn.demo import Demonstration
from lampskit.learn.synth import synthesize_demo

from .conftest import REAL_DEMOS


@pytest.fixture(scope="module")
def synth():
    return synthesize_demo(2, seed=3)


def test_csv_round_trip_is_exact_to_print_precision(tmp_path, synth):
    path = demo_io.write_demo_csv(tmp_path / "d.csv", synth.demo)
    back = demo_io.read_demo(path)
    np.testing.assert_allclose(back.t_s, synth.demo.t_s, atol=1e-8)
    np.testing.assert_allclose(back.position_m, synth.demo.position_m, atol=1e-8)
    np.testing.assert_allclose(back.orientation_wxyz, synth.demo.orientation_wxyz, atol=1e-8)


def test_npz_round_trip_is_exact(tmp_path, synth):
    back = demo_io.read_demo(demo_io.write_demo_npz(tmp_path / "d.npz", synth.demo))
    np.testing.assert_array_equal(back.position_m, synth.demo.position_m)
    np.testing.assert_array_equal(back.t_s, synth.demo.t_s)


def test_csv_without_orientation_and_with_extra_columns(tmp_path):
    t = np.arange(200) / 100.0
    lines = ["time_note,t,x,y,z"] + [f"a,{ti},{np.sin(ti)},{np.cos(ti)},0.5" for ti in t]
    (tmp_path / "d.csv").write_text("\n".join(lines))
    d = demo_io.read_demo(tmp_path / "d.csv")
    assert d.orientation_wxyz is None
    np.testing.assert_allclose(d.position_m[:, 0], np.sin(t))


def test_labels_round_trip(tmp_path, synth):
    path = demo_io.write_labels_csv(tmp_path / "l.csv", synth.demo.t_s, synth.true_periodic, synth.true_stain)
    np.testing.assert_array_equal(demo_io.read_labels(path, synth.demo.n_samples), synth.true_periodic)
    with pytest.raises(DemoError, match="labels for a demonstration of"):
        demo_io.read_labels(path, synth.demo.n_samples + 1)


@pytest.mark.parametrize(
    "content, match",
    [
        ("", "empty"),
        ("t,x,y,z\n", "no data rows"),
        ("t,x,y\n0,1,2\n", r"missing column\(s\) \['z'\]"),
        ("t,x,y,z,qx,qy\n" + "0,0,0,0,0,0\n" * 60, "orientation needs all of"),
        ("t,x,y,z\n" + "".join(f"{i / 100},0,0,0\n" for i in range(10)), "too short: 10 samples"),
        ("t,x,y,z\n" + "".join(f"{i / 100},{'nan' if i == 70 else 0},0,0\n" for i in range(200)), "NaN at sample 70"),
        ("t,x,y,z\n" + "".join(f"{i / 100},0,{'inf' if i == 5 else 0},0\n" for i in range(200)), "inf at sample 5"),
        ("t,x,y,z\n" + "".join(f"{(i if i != 50 else 10) / 100},0,0,0\n" for i in range(200)),
         "increase strictly: sample 50"),
        ("t,x,y,z\n" + "".join(f"{i / 100},0,abc,0\n" for i in range(200)), "'abc' is not a number"),
        ("t,x,y,z\n" + "".join(f"{i / 1000},0,0,0\n" for i in range(200)), r"too short: 0.199 s"),
    ],
)
def test_bad_csv_is_rejected_with_a_named_problem(tmp_path, content, match):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(DemoError, match=match):
        demo_io.read_demo(path)


def test_unknown_format_and_missing_file(tmp_path):
    (tmp_path / "d.json").write_text("{}")
    with pytest.raises(DemoError, match="unknown demonstration format '.json'"):
        demo_io.read_demo(tmp_path / "d.json")
    with pytest.raises(DemoError, match="no such file"):
        demo_io.read_demo(tmp_path / "nope.csv")


def test_corrupt_npz(tmp_path):
    (tmp_path / "d.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(DemoError, match="not a readable .npz"):
        demo_io.read_demo(tmp_path / "d.npz")


# --------------------------------------------------------------------------
# Qualisys QTM export with four markers on the eraser


def _eraser_markers(n: int, rate: float, rng):
    """True tool poses and four marker tracks (mm) of an eraser moving in circles while turning."""
    t = np.arange(n) / rate
    layout = np.array([[0.05, 0.02, 0.01], [-0.05, 0.02, 0.0], [-0.04, -0.02, 0.012], [0.05, -0.025, 0.0]])
    layout -= layout.mean(axis=0)
    pos = np.column_stack([0.5 + 0.05 * np.cos(4 * t), 0.1 * np.sin(4 * t), 0.3 + 0.01 * t])
    quats = []
    markers = np.empty((n, 4, 3))
    for k in range(n):
        a = 0.3 * np.sin(1.5 * t[k])
        R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        markers[k] = layout @ R.T + pos[k]
        quats.append(quat_wxyz_from_matrix(R))
    return t, pos, np.array(quats), markers


def _write_qtm(path, t, markers_m, with_time=True):
    names = [f"eraser{i + 1}" for i in range(markers_m.shape[1])]
    head = [
        f"NO_OF_FRAMES\t{len(t)}",
        "NO_OF_CAMERAS\t8",
        f"NO_OF_MARKERS\t{len(names)}",
        "FREQUENCY\t100",
        "NO_OF_ANALOG\t0",
        "ANALOG_FREQUENCY\t0",
        "DESCRIPTION\t--",
        "TIME_STAMP\t2024-05-01, 10:00:00",
        "DATA_INCLUDED\t3D",
        "MARKER_NAMES\t" + "\t".join(names),
    ]
    if with_time:
        head.append("Frame\tTime\t" + "\t".join(f"{n} {c}" for n in names for c in "XYZ"))
    rows = []
    mm = np.nan_to_num(markers_m * 1000.0, nan=0.0)
    for k in range(len(t)):
        vals = "\t".join(f"{v:.3f}" for v in mm[k].ravel())
        rows.append(f"{k + 1}\t{t[k]:.5f}\t{vals}" if with_time else vals)
    path.write_text("\n".join(head + rows) + "\n")


@pytest.mark.parametrize("with_time", [True, False])
def test_qtm_rigid_body_fit_recovers_the_tool_path(tmp_path, with_time):
    rng = np.random.default_rng(0)
    t, pos, quat, markers = _eraser_markers(400, 100.0, rng)
    markers = markers + rng.normal(0, 0.0002, markers.shape)
    markers[100:104, 2] = np.nan  # one marker hidden for 40 ms: three left, still a fit
    markers[200:205] = np.nan  # all hidden for 50 ms: bridged
    _write_qtm(tmp_path / "demo.tsv", t, markers, with_time)
    d = demo_io.read_demo(tmp_path / "demo.tsv")
    err = np.linalg.norm(d.position_m - pos, axis=1)
    assert err.max() < 0.002 and np.median(err) < 0.0005
    # orientation relative to the first frame matches the true relative rotation
    R0 = matrix_from_quat_wxyz(d.orientation_wxyz[0])
    for k in (50, 150, 300):
        rel = matrix_from_quat_wxyz(d.orientation_wxyz[k]) @ R0.T
        true_rel = matrix_from_quat_wxyz(quat[k]) @ matrix_from_quat_wxyz(quat[0]).T
        assert np.abs(rel - true_rel).max() < 0.02


def test_qtm_long_gap_and_swapped_marker_are_rejected(tmp_path):
    rng = np.random.default_rng(1)
    t, _, _, markers = _eraser_markers(300, 100.0, rng)
    gap = markers.copy()
    gap[100:130, :2] = np.nan
    _write_qtm(tmp_path / "gap.tsv", t, gap)
    with pytest.raises(DemoError, match="fewer than three markers seen"):
        demo_io.read_demo(tmp_path / "gap.tsv")
    swap = markers.copy()
    swap[150, [0, 2]] = swap[150, [2, 0]]
    _write_qtm(tmp_path / "swap.tsv", t, swap)
    with pytest.raises(DemoError, match="residual .* at frame 150"):
        demo_io.read_demo(tmp_path / "swap.tsv")


def test_qtm_without_header_is_rejected(tmp_path):
    (tmp_path / "x.tsv").write_text("1\t2\t3\n4\t5\t6\n")
    with pytest.raises(DemoError, match="not a QTM 3D export"):
        demo_io.read_demo(tmp_path / "x.tsv")


@pytest.mark.realdata
def test_real_mat_demos_and_labels_load():
    if not REAL_DEMOS.is_file():
        pytest.skip(f"real data absent: {REAL_DEMOS}")
    for i, n in enumerate([1238, 1096, 1457, 1120]):
        d = demo_io.read_demo(f"{REAL_DEMOS}#{i}")
        assert isinstance(d, Demonstration) and d.n_samples == n
        assert 70 < d.rate_hz < 110
        assert demo_io.read_labels(f"{REAL_DEMOS}#{i}", n).sum() > 0.4 * n
    with pytest.raises(DemoError, match="index 4 out of range"):
        demo_io.read_demo(f"{REAL_DEMOS}#4")
