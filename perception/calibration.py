"""A camera's intrinsics and lens distortion: read from the files users have, made from target images, undone.

* :func:`read_calibration` reads a ROS ``camera_info`` YAML (what
  ``camera_calibration`` and ``camera_info_manager`` write: ``image_width``,
  ``image_height``, ``camera_matrix``, ``distortion_model`` ``plumb_bob`` or
  ``rational_polynomial``, ``distortion_coefficients``) or an OpenCV
  ``FileStorage`` file (YAML or XML, as OpenCV's calibration samples write:
  ``camera_matrix`` / ``cameraMatrix`` / ``K`` and ``distortion_coefficients``
  / ``dist_coeffs`` / ``D``, optional ``image_width`` / ``image_height``).
* :meth:`Calibration.at` scales it to the frames' resolution (same aspect
  ratio only); :class:`Undistorter` undoes the distortion of each frame with
  maps made once, keeping the camera matrix, so markers, homographies and
  rectification downstream see an ideal pinhole camera.
* :func:`calibrate` runs OpenCV's own calibration on images of a chessboard
  (``chessboard:COLSxROWS:SQUARE_M``, inner corners) and :func:`write_camera_info`
  writes the result as a ROS ``camera_info`` YAML.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from interfaces.errors import ConfigError
from lampskit.atomic import write_text_atomic


class CalibrationError(ConfigError):
    """A calibration file or target that cannot be used; the message names the file and what is wrong."""


@dataclass(frozen=True)
class Calibration:
    """K (3, 3) [px] and distortion coefficients (n,) (OpenCV's order: k1 k2 p1 p2 [k3 [k4 k5 k6]]) for images of
    ``width`` x ``height`` px (0 x 0: unknown, taken as the frames')."""

    K: np.ndarray
    dist: np.ndarray
    width: int = 0
    height: int = 0

    def at(self, width: int, height: int) -> Calibration:
        """The calibration for frames of ``width`` x ``height`` (scaled; CalibrationError if the aspect differs)."""
        if not self.width or (self.width, self.height) == (width, height):
            return Calibration(self.K, self.dist, width, height)
        sx, sy = width / self.width, height / self.height
        if abs(sx - sy) > 0.01 * max(sx, sy):
            raise CalibrationError(f"calibrated for {self.width} x {self.height} px, frames are {width} x {height} px "
                                   "(another aspect ratio: calibrate at this resolution)")
        K = self.K.copy()
        K[0, :] *= sx
        K[1, :] *= sy
        K[2, :] = (0.0, 0.0, 1.0)
        return Calibration(K, self.dist, width, height)


def _matrix(node, name: str, path: Path) -> np.ndarray:
    if isinstance(node, dict) and "data" in node:
        data = np.asarray(node["data"], float)
        rows, cols = int(node.get("rows", 1)), int(node.get("cols", data.size))
        if data.size != rows * cols:
            raise CalibrationError(f"{path}: {name} has {data.size} values for {rows} x {cols}")
        return data.reshape(rows, cols)
    return np.asarray(node, float)


def _checked(K: np.ndarray, dist: np.ndarray, path: Path) -> tuple[np.ndarray, np.ndarray]:
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError(f"{path}: the camera matrix must be 3 x 3 with positive focal lengths, got {K.tolist()}")
    dist = dist.ravel()
    if dist.size not in (0, 4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
        raise CalibrationError(f"{path}: {dist.size} distortion coefficients (OpenCV takes 4, 5, 8, 12 or 14)")
    return K, dist


def read_calibration(path: str | Path) -> Calibration:
    """The calibration in ``path`` (ROS camera_info YAML or OpenCV FileStorage YAML / XML); CalibrationError."""
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f"calibration file {p} does not exist")
    text = p.read_text(encoding="utf-8", errors="replace")
    if "camera_matrix" in text and "%YAML" not in text[:20] and not text.lstrip().startswith("<"):
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise CalibrationError(f"{p}: not YAML ({str(exc).splitlines()[0]})") from None
        if isinstance(data, dict) and "camera_matrix" in data:
            model = data.get("distortion_model", "plumb_bob")
            if model not in ("plumb_bob", "rational_polynomial"):
                raise CalibrationError(f"{p}: distortion_model {model!r}: only plumb_bob and rational_polynomial "
                                       "(OpenCV's model) are read")
            K = _matrix(data["camera_matrix"], "camera_matrix", p)
            dist = _matrix(data.get("distortion_coefficients", {"data": []}), "distortion_coefficients", p)
            K, dist = _checked(K, dist, p)
            return Calibration(K, dist, int(data.get("image_width", 0) or 0), int(data.get("image_height", 0) or 0))
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError):  # OpenCV's parser raises on text that is no FileStorage format at all
        fs = None
    if fs is None or not fs.isOpened():
        raise CalibrationError(f"{p}: neither a ROS camera_info YAML nor an OpenCV calibration file")
    try:
        Ks = [fs.getNode(n).mat() for n in ("camera_matrix", "cameraMatrix", "K") if not fs.getNode(n).empty()]
        dist = next((fs.getNode(n).mat() for n in ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D")
                     if not fs.getNode(n).empty()), np.zeros(0))
        width = int(fs.getNode("image_width").real() or 0)
        height = int(fs.getNode("image_height").real() or 0)
    finally:
        fs.release()
    if not Ks:
        raise CalibrationError(f"{p}: no camera_matrix (or cameraMatrix, K) in it")
    K, dist = _checked(np.asarray(Ks[0], float), np.asarray(dist if dist is not None else [], float), p)
    return Calibration(K, dist, width, height)


class Undistorter:
    """Undoes a calibration's lens distortion on frames of one size (maps made once; the camera matrix kept)."""

    def __init__(self, calibration: Calibration) -> None:
        self.calibration = calibration
        self.active = bool(np.any(calibration.dist != 0.0))
        size = (calibration.width, calibration.height)
        self._maps = (cv2.initUndistortRectifyMap(calibration.K, calibration.dist, None, calibration.K, size,
                                                  cv2.CV_16SC2) if self.active else None)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """``image`` (H, W[, 3]) as an ideal pinhole camera with the same K would have seen it."""
        if self._maps is None:
            return image
        return cv2.remap(image, self._maps[0], self._maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


_PATTERN = re.compile(r"^chessboard:(\d+)x(\d+):([0-9.]+)$")


def parse_pattern(spec: str) -> tuple[tuple[int, int], float]:
    """``chessboard:COLSxROWS:SQUARE_M`` (inner corners, square side [m]) -> ((cols, rows), square_m)."""
    m = _PATTERN.match(spec)
    if not m or int(m.group(1)) < 3 or int(m.group(2)) < 3 or not 0.001 <= float(m.group(3)) <= 1.0:
        raise CalibrationError(f"--pattern must be chessboard:COLSxROWS:SQUARE_M with at least 3 x 3 inner corners "
                               f"and a square of 0.001-1 m, got {spec!r}")
    return (int(m.group(1)), int(m.group(2))), float(m.group(3))


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` found: the calibration, the RMS reprojection error [px], images used and skipped."""

    calibration: Calibration
    rms_px: float
    used: tuple[str, ...]
    skipped: tuple[str, ...]


def calibrate(images: list[Path], pattern: str) -> CalibrationResult:
    """OpenCV's calibration (``cv2.calibrateCamera``, k1 k2 p1 p2 k3) from chessboard images; CalibrationError."""
    (cols, rows), square = parse_pattern(pattern)
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    obj_pts, img_pts, used, skipped, size = [], [], [], [], None
    for path in images:
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if grey is None:
            skipped.append(f"{path.name}: not an image")
            continue
        if size is not None and grey.shape[::-1] != size:
            skipped.append(f"{path.name}: {grey.shape[1]} x {grey.shape[0]} px, the others {size[0]} x {size[1]}")
            continue
        ok, corners = cv2.findChessboardCorners(grey, (cols, rows), None,
                                                flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            skipped.append(f"{path.name}: no {cols} x {rows} chessboard found")
            continue
        size = grey.shape[::-1]
        corners = cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4))
        obj_pts.append(obj)
        img_pts.append(corners)
        used.append(path.name)
    if len(used) < 3:
        raise CalibrationError(f"calibration needs the chessboard in at least 3 images, found it in {len(used)}"
                               + (f" ({'; '.join(skipped[:5])})" if skipped else ""))
    assert size is not None  # set with the first image the chessboard was found in
    rms, K, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, size, None, None)
    if not math.isfinite(rms):
        raise CalibrationError("OpenCV's calibration did not converge")
    return CalibrationResult(Calibration(K, dist.ravel(), size[0], size[1]), float(rms), tuple(used), tuple(skipped))


def write_camera_info(path: str | Path, calibration: Calibration, name: str = "camera") -> None:
    """``calibration`` as a ROS ``camera_info`` YAML (plumb_bob), atomically."""
    K, d = calibration.K, calibration.dist
    P = np.hstack([K, np.zeros((3, 1))])
    doc = {"image_width": int(calibration.width), "image_height": int(calibration.height), "camera_name": name,
           "camera_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in K.ravel()]},
           "distortion_model": "plumb_bob" if d.size <= 5 else "rational_polynomial",
           "distortion_coefficients": {"rows": 1, "cols": int(d.size), "data": [float(v) for v in d]},
           "rectification_matrix": {"rows": 3, "cols": 3, "data": [float(v) for v in np.eye(3).ravel()]},
           "projection_matrix": {"rows": 3, "cols": 4, "data": [float(v) for v in P.ravel()]}}
    write_text_atomic(Path(path), yaml.safe_dump(doc, sort_keys=False))
