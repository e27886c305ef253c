"""``lamps perception --check-board IMAGE``: which corner markers a photograph shows, the board's pose and size.

For setting up a real board: the markers of ``[perception.board]`` (any
dictionary, ids, size and inset) are detected in one image, each named by
its corner; with three or more the board's size is measured (or the
configured ``size_m`` used) and its pose solved with the camera model of
``[perception.camera_model]`` (or the default focal length for the image's width,
said so). The image is written back with the markers outlined and the
board's outline and axes drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from interfaces.board_markers import CORNERS

from .board import detect_markers, make_detector, measure_board, solve_pose
from .params import PerceptionParams
from .sources import camera_model, undistorter


@dataclass
class BoardCheck:
    """What one image shows. markers: id -> corners (4, 2) [px]; size_m (w, h) and T_board_to_camera (4, 4) when
    the board was found; rms_px: corner reprojection error; why: why not found ("" when found)."""

    shape: tuple[int, int]
    K: np.ndarray
    guessed_intrinsics: bool
    markers: dict[int, np.ndarray] = field(default_factory=dict)
    size_m: tuple[float, float] | None = None
    T_board_to_camera: np.ndarray | None = None
    rms_px: float = math.inf
    why: str = ""

    @property
    def found(self) -> bool:
        return self.T_board_to_camera is not None and not self.why


def check_board(bgr: np.ndarray, params: PerceptionParams) -> BoardCheck:
    """Detect the board's markers in ``bgr`` (H, W, 3) uint8 and solve its size and pose."""
    h, w = bgr.shape[:2]
    K, _ = camera_model(params.model, w, h)
    cam = params.model
    if cam.calibration:
        bgr = undistorter(cam.calibration, w, h)(bgr)
    out = BoardCheck((h, w), K, guessed_intrinsics=not (cam.fx and cam.fy or cam.calibration))
    layout = params.board.layout
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    out.markers = detect_markers(make_detector(layout), grey, layout.ids)
    if len(out.markers) < 3 and params.board.size_m == (0.0, 0.0):
        out.why = f"{len(out.markers)} of the 4 markers seen: 3 are needed to measure the board"
        return out
    if len(out.markers) < params.board.min_markers:
        out.why = f"{len(out.markers)} markers seen, min_markers is {params.board.min_markers}"
        return out
    try:
        if params.board.size_m == (0.0, 0.0):
            out.size_m, out.T_board_to_camera, out.rms_px = measure_board(out.markers, K, layout)
        else:
            out.size_m = params.board.size_m
            out.T_board_to_camera, out.rms_px = solve_pose(out.markers, out.size_m, K, layout=layout)
    except (ValueError, cv2.error) as exc:
        out.why = f"board pose failed: {str(exc).splitlines()[0][:80]}"
        return out
    if out.rms_px > params.board.max_reprojection_px:
        out.why = (f"markers reproject badly ({out.rms_px:.1f} px RMS, max_reprojection_px "
                   f"{params.board.max_reprojection_px}): wrong marker_side_m, ids or camera model?")
    return out


def report_lines(check: BoardCheck, params: PerceptionParams) -> list[str]:
    """What :func:`check_board` found, for a person."""
    layout = params.board.layout
    k = check.K
    lines = [f"image {check.shape[1]} x {check.shape[0]} px; camera fx {k[0, 0]:.0f} fy {k[1, 1]:.0f} cx {k[0, 2]:.0f} "
             f"cy {k[1, 2]:.0f} px" + (" (guessed: give [perception.camera_model] fx, fy, cx, cy)"
                                       if check.guessed_intrinsics else ""),
             f"markers {layout.dictionary}, side {layout.side_m} m, inset {layout.inset_m} m:"]
    for corner, mid in zip(CORNERS, layout.ids):
        seen = check.markers.get(mid)
        where = f"seen at ({seen[:, 0].mean():.0f}, {seen[:, 1].mean():.0f}) px" if seen is not None else "NOT SEEN"
        lines.append(f"  id {mid:>4} {corner:<12} {where}")
    if check.size_m is not None and check.T_board_to_camera is not None:
        t = check.T_board_to_camera[:3, 3]
        tilt = math.degrees(math.acos(float(np.clip(abs(check.T_board_to_camera[2, 2]), 0.0, 1.0))))
        lines.append(f"board {check.size_m[0]:.3f} x {check.size_m[1]:.3f} m, its corner at ({t[0]:.3f}, {t[1]:.3f}, "
                     f"{t[2]:.3f}) m from the camera, {tilt:.0f} deg off facing it; corners reproject to "
                     f"{check.rms_px:.2f} px RMS")
    lines.append("board found" if check.found else f"board NOT found: {check.why}")
    return lines


def draw(bgr: np.ndarray, check: BoardCheck) -> np.ndarray:
    """A copy of ``bgr`` with the markers outlined and labelled, the board's outline and axes drawn."""
    img = bgr.copy()
    thick = max(1, round(max(img.shape[:2]) / 500))
    for mid, c in check.markers.items():
        cv2.polylines(img, [np.round(c).astype(np.int32)], True, (0, 200, 0), thick)
        cv2.putText(img, str(mid), tuple(int(v) for v in c[0]), cv2.FONT_HERSHEY_SIMPLEX, 0.6 * thick, (0, 0, 255),
                    thick)
    if check.size_m is not None and check.T_board_to_camera is not None:
        w, h = check.size_m
        T = check.T_board_to_camera
        pts = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
        axes = np.array([[0, 0, 0], [0.1 * w, 0, 0], [0, 0.1 * w, 0], [0, 0, 0.1 * w]], float)
        rvec = cv2.Rodrigues(T[:3, :3])[0]
        outline, _ = cv2.projectPoints(pts, rvec, T[:3, 3], check.K, None)
        cv2.polylines(img, [np.round(outline.reshape(-1, 2)).astype(np.int32)], True, (255, 0, 255), thick)
        ax, _ = cv2.projectPoints(axes, rvec, T[:3, 3], check.K, None)
        ax = np.round(ax.reshape(-1, 2)).astype(np.int32)
        for end, colour in zip(ax[1:], ((0, 0, 255), (0, 255, 0), (255, 0, 0))):
            cv2.arrowedLine(img, tuple(ax[0]), tuple(end), colour, thick + 1)
    return img


def main_check_board(image: str, params: PerceptionParams, out: str | None) -> int:
    """The ``--check-board`` command: report, drawing at ``out`` (default ``<image>.board.png``); exit 0 if found."""
    import sys

    from lampskit.atomic import write_atomic

    bgr = cv2.imread(image, cv2.IMREAD_COLOR)
    if bgr is None:
        print(f"lamps perception: error: --check-board {image}: not an image OpenCV can read", file=sys.stderr)
        return 1
    try:
        check = check_board(bgr, params)
    except ValueError as exc:  # a calibration that does not fit the image
        print(f"lamps perception: error: {exc}", file=sys.stderr)
        return 1
    for line in report_lines(check, params):
        print(line)
    target = Path(out) if out else Path(image).with_suffix(".board.png")
    ok, png = cv2.imencode(".png", draw(bgr, check))
    if ok:
        write_atomic(target, lambda f: f.write(png.tobytes()))
        print(f"drawn: {target}")
    return 0 if check.found else 1
