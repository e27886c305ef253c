"""Several inks on real photographs against hand-made masks, and a wipe made from a real photograph.

The photographs and their masks: tests/fixtures/whiteboards (NOTICE, stains.toml, board.toml). A drawing is
scored where perception saw it (glare it reports as occluded is not scored, and how much of each mask it saw is
checked too); false stain area counts everywhere perception looked, glare included.
"""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest

from interfaces.errors import ConfigError
from perception.classify import InkClassifier
from perception.frames import Frame
from perception.params import InkParams, PerceptionParams
from perception.photo_score import score_photo
from perception.pipeline import Perception
from perception.sources import camera_model

from .conftest import REPO
from .whiteboard_sequence import Eraser, camera_frames

PHOTOS = REPO / "tests" / "fixtures" / "whiteboards"
NAMES = ("straight", "sideangle", "highangle")
LABELS = tomllib.loads((PHOTOS / "stains.toml").read_text())


@pytest.fixture(scope="module")
def params() -> PerceptionParams:
    return PerceptionParams.from_table(tomllib.loads((PHOTOS / "board.toml").read_text())["perception"])


@pytest.fixture(scope="module")
def scores(params):
    return {n: score_photo(cv2.imread(str(PHOTOS / f"{n}.jpg")), params, LABELS[n]["stains"]) for n in NAMES}


def test_every_ink_matches_its_hand_made_masks_where_it_is_seen(scores):
    for name, s in scores.items():
        for ink in s.scores:
            if ink.seen < 0.5:  # the window's glare saturates the camera over most of it: reported occluded
                continue
            assert ink.iou >= 0.7, (name, ink)
    seen = {(n, i.ink): i.seen for n, s in scores.items() for i in s.scores}
    assert sum(v >= 0.5 for v in seen.values()) >= 14, seen  # all 5 inks in 3 photos but one, under glare
    assert all(v == 1.0 for (n, _), v in seen.items() if n != "sideangle"), seen


def test_false_stain_area_is_under_half_a_percent_of_the_clean_board_glare_included(scores):
    for name, s in scores.items():
        assert s.false_area < 0.005, (name, s.false_area)
    # the side view's window glare and lamp spot are occluded (nothing measured where the sensor clips), the
    # other views see all of their board
    assert scores["sideangle"].occluded > 0.05
    assert scores["straight"].occluded < 0.01 and scores["highangle"].occluded < 0.01


def test_each_drawing_is_one_area_of_its_own_ink(scores):
    for name in ("straight", "highangle"):
        big = sorted(a.ink for a in scores[name].areas if a.ink_px > 300)
        assert big == sorted(st["ink"] for st in LABELS[name]["stains"]), (name, big)
    # the side view: the purple box mostly under the glare; what is left of it may pass for another ink
    big = sorted(a.ink for a in scores["sideangle"].areas if a.ink_px > 300)
    assert set(big) >= {"red", "blue", "green", "brown"} and len(big) <= 7, big


def test_the_simulators_default_palette_sees_none_of_this_real_board_as_its_ink(params):
    """The default (the simulator's blue ink, no local white) on a real photograph: the blue box is found, the
    other inks do not pass for blue."""
    from perception.check_board import check_board
    from perception.rectify import BoardGrid

    bgr = cv2.imread(str(PHOTOS / "straight.jpg"))
    c = check_board(bgr, params)
    grid = BoardGrid(c.size_m, 0.002)
    rect = grid.warp(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), grid.image_from_grid(c.K, c.T_board_to_camera))
    looked = grid.looked_at(0.01, 0.03, params.board.layout)
    ink = InkClassifier(InkParams(), looked, 0.002).classify(rect)
    assert ink.names == ("blue",)
    assert ink.stain[looked].mean() < 0.02


def test_a_palette_is_checked_naming_the_bad_ink():
    with pytest.raises(ConfigError, match=r"inks.pale .* must be darker"):
        InkParams(inks={"pale": (240, 240, 236)})
    with pytest.raises(ConfigError, match="ink name 'Blue!'"):
        InkParams(inks={"Blue!": (20, 30, 90)})
    with pytest.raises(ConfigError, match="1 to 8 named colours"):
        InkParams(inks={})
    with pytest.raises(ConfigError, match="clean_level 0.4 must be below stain_level 0.3"):
        InkParams(clean_level=0.4)


def test_a_palette_fitted_from_two_photographs_scores_as_well_on_the_third(params):
    """``--fit-inks``: each ink's colour from the labelled drawings of two photographs; on the third (not used to
    fit), every ink it sees matches its masks at IoU >= 0.7 and the false area stays under 0.5 %."""
    from dataclasses import replace

    from perception.fit_inks import fit_palette, stroke_absorptions

    photos = {n: cv2.imread(str(PHOTOS / f"{n}.jpg")) for n in NAMES}
    samples = {n: stroke_absorptions(photos[n], params, LABELS[n]["stains"]) for n in NAMES}
    for held_out in NAMES:
        fitted = fit_palette([samples[n] for n in NAMES if n != held_out], params.ink.board_rgb)
        assert sorted(fitted) == ["blue", "brown", "green", "purple", "red"]
        ink = replace(params.ink, inks={**params.ink.inks, **fitted})
        s = score_photo(photos[held_out], replace(params, ink=ink), LABELS[held_out]["stains"])
        assert s.false_area < 0.005, (held_out, s.false_area)
        for score in s.scores:
            assert score.seen < 0.5 or score.iou >= 0.7, (held_out, score, fitted)


def test_fit_inks_on_the_command_line_prints_the_palette_and_refuses_bad_input(tmp_path, capsys):
    from perception.cli import main as perception_main

    images = [str(PHOTOS / f"{n}.jpg") for n in ("straight", "highangle")]
    base = ["--config", str(PHOTOS / "board.toml"), "--no-zenoh", "--source", f"folder:{PHOTOS}"]
    assert perception_main([*base, "--fit-inks", *images, "--masks", str(PHOTOS / "stains.toml")]) == 0
    out = capsys.readouterr().out
    line = out.strip().splitlines()[-1]
    assert line.startswith("inks = { red = [") and "purple = [" in line, out
    assert InkParams(inks=tomllib.loads(line)["inks"]).ink_names == ("red", "blue", "green", "purple", "brown")
    assert perception_main([*base, "--fit-inks", *images]) == 1
    assert "needs --masks" in capsys.readouterr().err
    bad = tmp_path / "masks.toml"
    bad.write_text("[other]\nstains = []\n")
    assert perception_main([*base, "--fit-inks", images[0], "--masks", str(bad)]) == 1
    assert "has no [straight] stains" in capsys.readouterr().err


# -- a wipe made from a real photograph --------------------------------------------------------------------------

def _run(params, scenes, rng) -> list:
    """Messages of the frames of ``scenes`` [(bgr, frames)] at 10 Hz, one list of stains per frame."""
    p = Perception(params)
    K, T = camera_model(params.model, 1160, 870)
    out, seq = [], 0
    for scene, n in scenes:
        for img in camera_frames(scene, n, rng):
            r = p.process(Frame(cv2.cvtColor(img, cv2.COLOR_BGR2RGB), K, T, 0.1 * seq, seq))
            out.append(r.stains.stains if r.stains is not None else None)
            seq += 1
    return out


@pytest.fixture(scope="module")
def wipe(params):
    bgr = cv2.imread(str(PHOTOS / "straight.jpg"))
    eraser = Eraser(bgr, params, LABELS["straight"]["stains"])
    half = eraser.erased(["Email LaTeX"], half=["Email LaTeX"])
    ghost = eraser.erased(["Email LaTeX"], ghost=0.1)
    scenes = [(bgr, 20), (half, 15), (ghost, 25), (bgr, 25)]  # before, during, erased to a ghost, redrawn
    return _run(params, scenes, np.random.default_rng(7)), eraser


def _by_centre(stains, centre_m, within=0.05):
    near = [s for s in stains if np.hypot(*(np.array(s.centre_board_m) - centre_m)) < within]
    assert len(near) == 1, (centre_m, [(s.id, s.centre_board_m) for s in stains])
    return near[0]


def test_an_erased_stain_gets_kappa_an_untouched_one_never_and_a_redrawn_one_loses_it(wipe):
    msgs, eraser = wipe
    blue = np.mean(eraser.stains["Email LaTeX"], axis=0)
    first = next(m for m in msgs if m)
    sid = _by_centre(first, blue).id
    seq = [(i, next(s for s in m if s.id == sid)) for i, m in enumerate(msgs) if m]
    before = [s for i, s in seq if i < 20]
    during = [s for i, s in seq if 22 <= i < 35]
    erased = [s for i, s in seq if 35 <= i < 60]
    redrawn = [s for i, s in seq if 65 <= i]
    assert not any(s.kappa for s in before + during)
    assert all(0.3 < s.remaining < 0.7 for s in during[3:]), [s.remaining for s in during]  # half left
    assert erased[-1].kappa and erased[-1].remaining <= 0.03  # the ghost counts as clean
    assert sum(s.kappa for s in erased) >= len(erased) - 5  # within half a second of the eraser's pass
    assert not any(s.kappa for s in redrawn) and all(s.remaining > 0.5 for s in redrawn)
    assert first[0].colour and all(s.colour == "blue" for _, s in seq)
    # the untouched drawings: never kappa, each one stain of its own ink
    for m in msgs:
        if m:
            assert not any(s.kappa for s in m if s.id != sid)


def test_ids_and_centres_stay_put_over_frames_of_one_scene(wipe):
    msgs, eraser = wipe
    last = msgs[-1]
    assert sorted(s.colour for s in last) == sorted(st["ink"] for st in LABELS["straight"]["stains"])
    for label, poly in eraser.stains.items():
        s = _by_centre(last, np.mean(poly, axis=0), within=0.06)
        track = [next(x for x in m if x.id == s.id) for m in msgs[-20:]]  # the last two seconds: one scene
        centres = np.array([x.centre_board_m for x in track])
        assert np.ptp(centres, axis=0).max() < 0.005, (label, np.ptp(centres, axis=0))
    ids = [sorted(s.id for s in m) for m in msgs[-20:]]
    assert all(i == ids[0] for i in ids)
