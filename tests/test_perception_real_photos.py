"""Perception's board finding on real photographs nobody here drew (tests/fixtures/whiteboards, NOTICE).

Three phone photographs of one real whiteboard from the front, the side and above: ArUco markers of another
dictionary (DICT_6X6_250), other ids and size than the cell's, several inks, a window's glare. The board layout
comes from configuration (board.toml); ``lamps perception --check-board`` must find every marker at its corner
and the board in each photo, and the three measurements of the one board must agree.
"""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest

from interfaces.errors import ConfigError
from perception.check_board import check_board, draw
from perception.cli import main as perception_main
from perception.params import BoardParams, PerceptionParams

from .conftest import REPO

PHOTOS = REPO / "tests" / "fixtures" / "whiteboards"
NAMES = ("straight", "sideangle", "highangle")


@pytest.fixture(scope="module")
def params() -> PerceptionParams:
    return PerceptionParams.from_table(tomllib.loads((PHOTOS / "board.toml").read_text())["perception"])


@pytest.fixture(scope="module")
def checks(params):
    return {n: check_board(cv2.imread(str(PHOTOS / f"{n}.jpg")), params) for n in NAMES}


def test_every_marker_is_found_at_its_corner_and_the_board_in_every_photo(checks, params):
    for name, c in checks.items():
        assert sorted(c.markers) == [1, 2, 3, 4], (name, sorted(c.markers))
        assert c.found, (name, c.why)
        centres = {i: m.mean(axis=0) for i, m in c.markers.items()}
        # id 1 top-left, 2 top-right, 3 bottom-right, 4 bottom-left in the image (upright photos)
        assert centres[1][0] < centres[2][0] and centres[4][0] < centres[3][0], name
        assert centres[1][1] < centres[4][1] and centres[2][1] < centres[3][1], name


def test_the_three_views_measure_the_same_board(checks):
    sizes = np.array([c.size_m for c in checks.values()])
    spread = (sizes.max(axis=0) - sizes.min(axis=0)) / sizes.mean(axis=0)
    assert np.all(spread < 0.06), sizes
    assert 2.2 < sizes[:, 0].mean() / sizes[:, 1].mean() < 2.8, sizes  # the drawn rectangle: about 2.5 : 1


def test_the_default_layout_finds_nothing_on_these_photos_and_says_why():
    c = check_board(cv2.imread(str(PHOTOS / "straight.jpg")), PerceptionParams())
    assert not c.found and not c.markers and "0 of the 4 markers" in c.why


def test_check_board_on_the_command_line_reports_and_draws(tmp_path, capsys):
    out = tmp_path / "drawn.png"
    rc = perception_main(["--config", str(PHOTOS / "board.toml"), "--no-zenoh", "--source", f"folder:{PHOTOS}",
                          "--check-board", str(PHOTOS / "sideangle.jpg"), "--board-image", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "id    1 top-left" in text and "board found" in text and "(guessed" in text
    drawn = cv2.imread(str(out))
    assert drawn is not None and drawn.shape == (870, 1160, 3)
    rc = perception_main(["--no-zenoh", "--source", f"folder:{PHOTOS}", "--check-board", str(PHOTOS / "NOTICE"),
                          "--board-image", str(tmp_path / "x.png")])
    assert rc == 1 and "not an image" in capsys.readouterr().err


def test_a_bad_marker_layout_is_refused_naming_it():
    with pytest.raises(ConfigError, match="dictionary must be one of"):
        BoardParams(dictionary="DICT_9X9_1")
    with pytest.raises(ConfigError, match=r"marker ids must be 4 different integers in \[0, 50\)"):
        BoardParams(marker_ids=(0, 1, 2, 50))
    with pytest.raises(ConfigError, match="marker ids"):
        BoardParams(marker_ids=(0, 0, 1, 2))
    assert BoardParams(dictionary="DICT_APRILTAG_36h11", marker_ids=[10, 11, 12, 13]).layout.ids == (10, 11, 12, 13)


def test_the_drawing_outlines_the_board(checks):
    c = checks["straight"]
    img = draw(cv2.imread(str(PHOTOS / "straight.jpg")), c)
    assert (img != cv2.imread(str(PHOTOS / "straight.jpg"))).any()


def test_offline_debug_images_are_written_where_asked(tmp_path, capsys):
    out = tmp_path / "debug"
    rc = perception_main(["--config", str(PHOTOS / "board.toml"), "--no-zenoh", "--source", f"folder:{PHOTOS}",
                          "--debug-images", "--debug-dir", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    written = sorted(out.glob("frame-*.jpg"))
    assert len(written) == 3 and all(cv2.imread(str(p)) is not None for p in written), (written, text)
    assert f"debug images: {out}/" in text
