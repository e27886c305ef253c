"""Camera calibration for perception on real cameras: the files users have, OpenCV's calibration, undistortion.

Chessboard images are rendered here through a known pinhole camera with known lens distortion (every pixel's ray
traced to the board plane through OpenCV's own distortion model), so what the calibration recovers and what the
undistortion straightens can be checked against the truth.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from interfaces.errors import ConfigError
from perception.calibration import (
    Calibration,
    CalibrationError,
    Undistorter,
    calibrate,
    parse_pattern,
    read_calibration,
    write_camera_info,
)
from perception.cli import main as perception_main
from perception.params import CameraModelParams

K_TRUE = np.array([[600.0, 0.0, 322.0], [0.0, 600.0, 238.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.28, 0.09, 0.0, 0.0, 0.0])
SIZE = (640, 480)
COLS, ROWS, SQUARE = 9, 6, 0.03


def render_chessboard(K, dist, rvec, tvec, size=SIZE) -> np.ndarray:
    """A grey (H, W) image of a COLS x ROWS (inner corners) chessboard with square SQUARE seen by (K, dist)."""
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    ideal = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), K, dist,
                                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9)).reshape(-1, 2)
    R = cv2.Rodrigues(np.asarray(rvec, float))[0]
    t = np.asarray(tvec, float)
    d = np.column_stack([ideal, np.ones(len(ideal))]) @ R  # rays in the board frame: R^T d
    o = -R.T @ t  # the camera centre in the board frame
    s = -o[2] / d[:, 2]
    xy = o[:2] + s[:, None] * d[:, :2]
    i, j = np.floor(xy[:, 0] / SQUARE), np.floor(xy[:, 1] / SQUARE)
    inside = (i >= -1) & (i <= COLS - 1) & (j >= -1) & (j <= ROWS - 1)
    margin = (i >= -2) & (i <= COLS) & (j >= -2) & (j <= ROWS) & (s > 0)
    img = np.where(inside & (s > 0), np.where((i + j) % 2 == 0, 30, 225), np.where(margin, 225, 128))
    return cv2.GaussianBlur(img.reshape(h, w).astype(np.uint8), (0, 0), 0.8)


POSES = [((0.0, 0.0, 0.0), (-0.12, -0.075, 0.45)), ((0.35, 0.0, 0.0), (-0.12, -0.07, 0.45)),
         ((-0.3, 0.25, 0.05), (-0.16, -0.08, 0.5)), ((0.0, -0.4, 0.0), (-0.08, -0.08, 0.42)),
         ((0.2, 0.3, 0.3), (-0.13, -0.1, 0.5)), ((-0.25, -0.2, -0.2), (-0.1, -0.05, 0.4)),
         ((0.1, 0.0, 0.6), (-0.08, -0.13, 0.45)), ((0.0, 0.35, -0.4), (-0.14, -0.04, 0.47))]


@pytest.fixture(scope="module")
def target_images(tmp_path_factory):
    d = tmp_path_factory.mktemp("chessboard")
    for n, (r, t) in enumerate(POSES):
        cv2.imwrite(str(d / f"view{n}.png"), render_chessboard(K_TRUE, DIST_TRUE, r, t))
    (d / "notes.txt").write_text("not an image")
    return d


def test_opencvs_calibration_recovers_the_camera_from_chessboard_images(target_images, tmp_path, capsys):
    result = calibrate(sorted(target_images.glob("*.png")), f"chessboard:{COLS}x{ROWS}:{SQUARE}")
    K, d = result.calibration.K, result.calibration.dist
    assert len(result.used) == len(POSES) and result.rms_px < 0.5, (result.used, result.skipped, result.rms_px)
    assert np.allclose(np.diag(K)[:2], [600.0, 600.0], rtol=0.02), K
    assert np.allclose(K[:2, 2], [322.0, 238.0], atol=6.0), K
    # the coefficients trade off against each other (k2 against k3): the lens they describe must be the true one,
    # so undoing it straightens a view the calibration never saw as well as the true lens does
    view = render_chessboard(K_TRUE, DIST_TRUE, (0.15, 0.1, 0.0), (-0.12, -0.075, 0.3))
    bent, by_truth = _residual(view), _residual(Undistorter(Calibration(K_TRUE, DIST_TRUE, *SIZE))(view))
    by_calibration = _residual(Undistorter(result.calibration)(view))
    assert by_calibration < 0.25 * bent and by_calibration < by_truth + 0.1, (bent, by_truth, by_calibration)
    out = tmp_path / "camera_info.yaml"
    rc = perception_main(["--calibrate", str(target_images), "--pattern", f"chessboard:{COLS}x{ROWS}:{SQUARE}",
                          "--calibration-out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and "calibrated from 8 of 8 images" in text, text
    back = read_calibration(out)
    assert back.width == 640 and np.allclose(back.K, K, rtol=1e-3) and np.allclose(back.dist, d, atol=1e-6)


def _residual(image) -> float:
    """RMS [px] of the chessboard's corners in ``image`` about the best homography of the flat board: 0 for an
    ideal pinhole camera, growing with lens distortion."""
    ideal = np.mgrid[0:COLS, 0:ROWS].T.reshape(-1, 2).astype(np.float32) * SQUARE
    ok, corners = cv2.findChessboardCorners(image, (COLS, ROWS))
    assert ok
    corners = cv2.cornerSubPix(image, corners, (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)).reshape(-1, 2)
    H, _ = cv2.findHomography(ideal, corners)
    proj = cv2.perspectiveTransform(ideal.reshape(-1, 1, 2), H).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum((proj - corners) ** 2, axis=1))))


def test_undistortion_straightens_what_the_lens_bent():
    img = render_chessboard(K_TRUE, DIST_TRUE, (0.15, 0.1, 0.0), (-0.12, -0.075, 0.3))  # filling the image
    bent = _residual(img)
    straight = _residual(Undistorter(Calibration(K_TRUE, DIST_TRUE, *SIZE))(img))
    assert bent > 1.5 and straight < 0.25 * bent, (bent, straight)


def test_ros_camera_info_and_opencv_files_read_alike_and_scale_to_the_frames(tmp_path):
    cal = Calibration(K_TRUE, DIST_TRUE, *SIZE)
    write_camera_info(tmp_path / "ros.yaml", cal)
    doc = yaml.safe_load((tmp_path / "ros.yaml").read_text())
    assert doc["distortion_model"] == "plumb_bob" and doc["camera_matrix"]["data"][0] == 600.0
    fs = cv2.FileStorage(str(tmp_path / "cv.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", K_TRUE)
    fs.write("distortion_coefficients", DIST_TRUE.reshape(1, -1))
    fs.release()
    for name in ("ros.yaml", "cv.yaml"):
        got = read_calibration(tmp_path / name)
        assert np.allclose(got.K, K_TRUE) and np.allclose(got.dist, DIST_TRUE) and (got.width, got.height) == SIZE
    half = read_calibration(tmp_path / "ros.yaml").at(320, 240)
    assert np.allclose(half.K[:2], K_TRUE[:2] / 2) and half.K[2, 2] == 1.0
    with pytest.raises(CalibrationError, match="another aspect ratio"):
        read_calibration(tmp_path / "ros.yaml").at(640, 360)


def test_bad_calibration_input_is_refused_naming_the_problem(tmp_path):
    with pytest.raises(CalibrationError, match="does not exist"):
        read_calibration(tmp_path / "nope.yaml")
    (tmp_path / "bad.yaml").write_text("camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\n")
    with pytest.raises(CalibrationError, match="has 3 values for 3 x 3"):
        read_calibration(tmp_path / "bad.yaml")
    (tmp_path / "fish.yaml").write_text("camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n"
                                        "distortion_model: equidistant\n")
    with pytest.raises(CalibrationError, match="only plumb_bob and rational_polynomial"):
        read_calibration(tmp_path / "fish.yaml")
    (tmp_path / "text.txt").write_text("hello")
    with pytest.raises(CalibrationError, match="neither a ROS camera_info"):
        read_calibration(tmp_path / "text.txt")
    with pytest.raises(CalibrationError, match="chessboard:COLSxROWS:SQUARE_M"):
        parse_pattern("checkers:9x6")
    with pytest.raises(ConfigError, match="calibration or fx, fy, cx, cy, not both"):
        CameraModelParams(fx=500.0, calibration="cam.yaml")
    with pytest.raises(CalibrationError, match="at least 3 images"):
        calibrate([tmp_path / "text.txt"], "chessboard:9x6:0.03")
