"""Surface frame fitting: plane, outward normal, 'up the board' axis, round trips."""

from __future__ import annotations

import numpy as np
import pytest

from lampskit.core.surface import fit_surface_frame
from lampskit.errors import LearningError
from lampskit.learn.synth import synthesize_demo


@pytest.mark.parametrize("seed", range(4))
def test_synthetic_board_frame_is_recovered(seed):
    s = synthesize_demo(3, seed)
    pts = s.demo.position_m
    frame = fit_surface_frame(pts[s.true_periodic], pts)
    R_true = s.T_board_to_world[:3, :3]
    R = frame.T_surface_to_world[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) > 0
    # the normal points out of the board, toward where the tool approaches from
    assert R[:, 2] @ R_true[:, 2] > 0.99
    # y is "up the board": close to the board's own y (which is world-up, tilted slightly)
    assert R[:, 1] @ R_true[:, 1] > 0.99
    assert frame.rms_off_plane_m < 0.002
    back = frame.world_from_surface(frame.surface_from_world(pts))
    np.testing.assert_allclose(back, pts, atol=1e-12)


def test_horizontal_table_uses_world_y_as_up():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.2, 0.2, (500, 2))
    pts = np.column_stack([xy, np.full(500, 0.8)])
    above = pts + [0, 0, 0.1]
    frame = fit_surface_frame(pts, np.vstack([pts, above]))
    R = frame.T_surface_to_world[:3, :3]
    np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(R[:, 1], [0, 1, 0], atol=1e-9)


def test_degenerate_inputs_are_rejected():
    with pytest.raises(LearningError, match="at least 3 points"):
        fit_surface_frame(np.zeros((2, 3)))
    line = np.outer(np.linspace(0, 1, 50), [1.0, 2.0, 3.0])
    with pytest.raises(LearningError, match="lie on a line"):
        fit_surface_frame(line)
