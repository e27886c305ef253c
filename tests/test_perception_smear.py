"""A smear is a state (perception/smear.py): passes that no longer lower a stain's remaining ink make it smeared,
on the logic's own series and on a wipe made from a real photograph with a heavy ghost."""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest

from interfaces.errors import ConfigError
from perception.frames import Frame
from perception.params import PerceptionParams
from perception.pipeline import Perception
from perception.smear import SmearParams, SmearWatch
from perception.sources import camera_model

from .test_perception_inks import LABELS, PHOTOS
from .whiteboard_sequence import Eraser, camera_frames

#: The eraser over a drawing, as the camera sees it: a saturated orange (clipped: occluded, never ink).
ERASER_BGR = (0, 140, 255)


def passes(watch: SmearWatch, remaining_after: list[float], kappa: bool = False):
    """Feed one pass per value: hidden, then back in view with that remaining; the last answer."""
    out = None
    for r in remaining_after:
        watch.update(1, r, 0.1, False)
        out = watch.update(1, r, 1.0, kappa)
    return out


def test_passes_without_progress_make_a_smear_and_progress_or_kappa_end_it():
    watch = SmearWatch(SmearParams(passes=3, min_progress=0.05))
    watch.update(1, 1.0, 1.0, False)
    assert passes(watch, [0.6, 0.3]) is None  # progress
    assert passes(watch, [0.29, 0.28]) is None  # two passes without
    smear = passes(watch, [0.28])
    assert smear is not None and smear.passes == 5 and smear.remaining == pytest.approx(0.28)
    assert watch.smeared() == [smear]
    assert passes(watch, [0.1]) is None  # progress again
    assert passes(watch, [0.1, 0.1, 0.1], kappa=True) is None  # clean is not smeared
    # hidden without coming back, or back only half in view, is no pass
    w = SmearWatch(SmearParams(passes=1))
    w.update(2, 0.5, 1.0, False)
    w.update(2, 0.5, 0.2, False)
    assert w.update(2, 0.5, 0.7, False) is None and w.update(2, 0.5, 0.95, False) is not None
    with pytest.raises(ConfigError, match="passes"):
        SmearParams(passes=0)


def test_a_return_is_a_pass_only_with_the_pad_on_the_stain_meanwhile_when_the_pad_is_known():
    from perception.self_filter import PAD_ON_BOARD_M, pad_footprint, tool_corners
    from perception.smear import pad_over

    w = SmearWatch(SmearParams(passes=2))
    w.update(1, 0.5, 1.0, False, False)
    for _ in range(5):  # the arm hides it and uncovers it, the pad elsewhere
        w.update(1, 0.5, 0.1, False, False)
        assert w.update(1, 0.5, 1.0, False, False) is None
    assert w.passes(1) == 0
    w.update(1, 0.5, 0.6, False, True)  # the pad arrives on it (still half in view), then hides it
    w.update(1, 0.5, 0.1, False, False)
    w.update(1, 0.5, 1.0, False, False)
    w.update(1, 0.5, 0.1, False, True)
    assert w.update(1, 0.5, 1.0, False, False) is not None and w.passes(1) == 2  # two passes without progress
    # the 12 x 5 cm pad's face flat on a board at z = 0 (TCP z into the board), its centre 8 cm left of a stain at
    # (0.3, 0.3) m: its edge 2 cm from the stain's centre
    T = np.eye(4)
    R = np.diag([1.0, -1.0, -1.0])
    on = pad_footprint(tool_corners(np.array([0.22, 0.3, 0.004]), R), T)
    assert on is not None and pad_over(on, np.array([0.3, 0.3]), 0.03) and not pad_over(on, np.array([0.3, 0.3]), 0.01)
    assert pad_footprint(tool_corners(np.array([0.25, 0.3, PAD_ON_BOARD_M + 0.01]), R), T) is None
    assert not pad_over(None, np.array([0.3, 0.3]), 1.0)


@pytest.fixture(scope="module")
def params():
    return PerceptionParams.from_table(tomllib.loads((PHOTOS / "board.toml").read_text())["perception"])


def test_a_heavy_ghost_wiped_again_and_again_is_a_smear_an_untouched_drawing_never(params):
    bgr = cv2.imread(str(PHOTOS / "straight.jpg"))
    eraser = Eraser(bgr, params, LABELS["straight"]["stains"])
    label = "Email LaTeX"
    smeared = eraser.erased([label], ghost=0.35)
    over = smeared.copy()
    over[eraser._mask(label) > 0] = ERASER_BGR  # the eraser on the drawing
    scenes = [(bgr, 6)] + [(over, 3), (smeared, 5)] * 5
    rng = np.random.default_rng(3)
    K, T = camera_model(params.model, bgr.shape[1], bgr.shape[0])
    p = Perception(params)
    watch = SmearWatch(SmearParams(passes=3))
    centre = np.mean(eraser.stains[label], axis=0)
    seq, first_smear, last = 0, None, None
    for scene, n in scenes:
        for img in camera_frames(scene, n, rng):
            r = p.process(Frame(cv2.cvtColor(img, cv2.COLOR_BGR2RGB), K, T, 0.1 * seq, seq))
            seq += 1
            if r.stains is None:
                continue
            last = r.stains.stains
            for s in last:
                got = watch.update(s.id, s.remaining, s.visible, s.kappa)
                if got is not None and first_smear is None:
                    first_smear = (seq, s)
    target = next(s for s in last if np.hypot(*(np.array(s.centre_board_m) - centre)) < 0.05)
    smears = watch.smeared()
    assert [m.stain_id for m in smears] == [target.id]  # only the wiped drawing, none of the untouched five
    m = smears[0]
    assert 0.1 < m.remaining < 0.6 and not target.kappa  # ink left, never judged clean
    assert m.passes == 5 and first_smear is not None
