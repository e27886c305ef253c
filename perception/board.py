"""The board from its corner markers: detection, size, pose, and the rectifying homography.

The markers follow a :class:`~interfaces.board_markers.MarkerLayout` (the
cell's default: ids 0-3 of ``DICT_4X4_50`` at the corners; ``[perception.board]``
names another). Each frame: detect the markers, solve the
board pose from every visible marker corner (a planar PnP, board frame z = 0),
refuse it if the corners reproject badly, unless one marker alone disagrees
(:func:`solve_pose_without_worst`: the arm cutting across a marker moves its
detected corners). The board size, unless configured,
is measured once from the markers (:func:`measure_board`: each marker's own
pose gives its centre, the centres' spacing along the board axes gives the
width and height, then pose and size are refined together on all corners).

:class:`BoardTracker` keeps the last good estimate through frames where the
arm hides the markers, for ``hold_s``; then the board is lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from interfaces.board_markers import DEFAULT_LAYOUT, MarkerLayout

from .params import BoardParams

#: A marker is looked for again within this share of its size around its last corners.
WINDOW_PAD = 0.6
#: ... and at least this many pixels (the detector's threshold windows and corner refinement fit inside) [px].
WINDOW_MIN_PX = 32


def make_detector(layout: MarkerLayout = DEFAULT_LAYOUT) -> cv2.aruco.ArucoDetector:
    """An ArUco detector for the layout's dictionary with sub-pixel corner refinement."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, layout.dictionary)), params)


def detect_markers(detector: cv2.aruco.ArucoDetector, grey: np.ndarray,
                   ids_wanted: tuple[int, ...] = DEFAULT_LAYOUT.ids) -> dict[int, np.ndarray]:
    """Corners (4, 2) [px] of each board marker seen in ``grey`` (H, W) uint8, by id (other ids ignored)."""
    corners, ids, _ = detector.detectMarkers(grey)
    if ids is None:
        return {}
    out: dict[int, np.ndarray] = {}
    for c, i in zip(corners, ids.ravel()):
        if int(i) in ids_wanted and int(i) not in out:
            out[int(i)] = c.reshape(4, 2).astype(np.float64)
    return out


def _transform(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, float).ravel()
    return T


def _board_points(markers: dict[int, np.ndarray], size_m: tuple[float, float],
                  layout: MarkerLayout = DEFAULT_LAYOUT) -> tuple[np.ndarray, np.ndarray]:
    """Object points (n, 3) in the board frame and image points (n, 2) of the visible marker corners."""
    board = layout.corners(size_m)
    ids = sorted(markers)
    obj = np.concatenate([np.column_stack([board[i], np.zeros(4)]) for i in ids])
    img = np.concatenate([markers[i] for i in ids])
    return obj, img


def reprojection_rms(obj: np.ndarray, img: np.ndarray, K: np.ndarray, T_board_to_camera: np.ndarray) -> float:
    """RMS distance [px] between ``img`` (n, 2) and the projections of ``obj`` (n, 3)."""
    rvec = cv2.Rodrigues(T_board_to_camera[:3, :3])[0]
    proj, _ = cv2.projectPoints(obj, rvec, T_board_to_camera[:3, 3], K, None)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def solve_pose(markers: dict[int, np.ndarray], size_m: tuple[float, float], K: np.ndarray,
               guess: np.ndarray | None = None, layout: MarkerLayout = DEFAULT_LAYOUT) -> tuple[np.ndarray, float]:
    """``(T_board_to_camera (4, 4), rms_px)`` from the visible markers' corners (a planar PnP)."""
    obj, img = _board_points(markers, size_m, layout)
    if guess is not None:
        rvec = cv2.Rodrigues(guess[:3, :3])[0]
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, None, rvec, guess[:3, 3].copy(), useExtrinsicGuess=True,
                                      flags=cv2.SOLVEPNP_ITERATIVE)
    else:
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, None, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return np.eye(4), math.inf
    T = _transform(rvec, tvec)
    return T, reprojection_rms(obj, img, K, T)


def solve_pose_without_worst(markers: dict[int, np.ndarray], size_m: tuple[float, float], K: np.ndarray,
                             guess: np.ndarray | None, layout: MarkerLayout,
                             max_rms_px: float) -> tuple[np.ndarray, float, int] | None:
    """``(T_board_to_camera (4, 4), rms_px, left_out_id)`` from all the markers but the one whose leaving out
    reprojects best, when that is within ``max_rms_px``; None when no single marker explains a bad fit (or
    fewer than three are seen, when leaving one out leaves too little to judge by).

    A marker the arm cuts across is still decoded, with a corner on the arm's edge: one marker off by a few
    pixels pulls the four-marker fit over the limit, while the other three agree to half a pixel (board 20 of
    the random campaign, as its camera recorded it: 2.2 px with all four, 0.5 px without the cut one). The
    board has not moved and is no other board: its size and its stains stay.
    """
    if len(markers) < 3:
        return None
    best: tuple[np.ndarray, float, int] | None = None
    for left_out in sorted(markers):
        T, rms = solve_pose({i: c for i, c in markers.items() if i != left_out}, size_m, K, guess, layout)
        if rms <= max_rms_px and (best is None or rms < best[1]):
            best = (T, rms, left_out)
    return best


def measure_board(markers: dict[int, np.ndarray], K: np.ndarray,
                  layout: MarkerLayout = DEFAULT_LAYOUT) -> tuple[tuple[float, float], np.ndarray, float]:
    """``(size_m (w, h), T_board_to_camera, rms_px)`` from at least three markers, or ValueError.

    Each marker's pose (PnP on its own square) gives its centre and axes;
    centres of markers in different columns give the width, in different
    rows the height; pose and size are then refined together on all corners.
    """
    if len(markers) < 3:
        raise ValueError(f"measuring the board needs 3 markers, saw {sorted(markers)}")
    s = layout.side_m
    square = np.array([[-s / 2, s / 2, 0], [s / 2, s / 2, 0], [s / 2, -s / 2, 0], [-s / 2, -s / 2, 0]])
    centres, axes = {}, []
    for i, c in markers.items():
        ok, rvec, tvec = cv2.solvePnP(square, c, K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if ok:
            T = _transform(rvec, tvec)
            centres[i] = T[:3, 3]
            axes.append(T[:3, :3])
    # the average marker orientation: board x and y in the camera frame
    u, _, vt = np.linalg.svd(sum(axes))
    R = u @ vt
    col = {i: (0, 1, 1, 0)[layout.corner_index(i)] for i in markers}
    row = {i: (0, 0, 1, 1)[layout.corner_index(i)] for i in markers}
    widths, heights = [], []
    ids = sorted(centres)
    for a_i, i in enumerate(ids):
        for j in ids[a_i + 1:]:
            d = centres[j] - centres[i]
            if col[i] != col[j]:
                widths.append(abs(d @ R[:, 0]) + 2 * layout.centre_inset_m)
            if row[i] != row[j]:
                heights.append(abs(d @ R[:, 1]) + 2 * layout.centre_inset_m)
    if not widths or not heights:
        raise ValueError(f"markers {ids} do not span both board axes")
    size0 = (float(np.mean(widths)), float(np.mean(heights)))
    T0, _ = solve_pose(markers, size0, K, layout=layout)

    def residual(x: np.ndarray) -> np.ndarray:
        obj, img = _board_points(markers, (x[6], x[7]), layout)
        proj, _ = cv2.projectPoints(obj, x[:3], x[3:6], K, None)
        return (proj.reshape(-1, 2) - img).ravel()

    x0 = np.concatenate([cv2.Rodrigues(T0[:3, :3])[0].ravel(), T0[:3, 3], size0])
    x = least_squares(residual, x0, method="lm").x
    size = (float(x[6]), float(x[7]))
    T = _transform(x[:3], x[3:6])
    obj, img = _board_points(markers, size, layout)
    return size, T, reprojection_rms(obj, img, K, T)


def pose_distance(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """Translation [m] and rotation [deg] between two (4, 4) poses."""
    dR = T_a[:3, :3].T @ T_b[:3, :3]
    angle = math.degrees(math.acos(float(np.clip((np.trace(dR) - 1.0) / 2.0, -1.0, 1.0))))
    return float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3])), angle


@dataclass(frozen=True)
class BoardEstimate:
    """The board as last seen.

    T_board_to_world : (4, 4). T_board_to_camera : (4, 4). size_m : (w, h).
    state : ``"seen"`` (this frame), ``"held"`` (the last good pose, markers
    hidden for less than ``hold_s``) or ``"lost"``. markers : ids seen this
    frame. t_s : time of the last good pose [s]. moved : the pose jumped
    (another board, or this one moved): what was known about its stains is
    void. reason : why not ``"seen"``.
    """

    T_board_to_world: np.ndarray
    T_board_to_camera: np.ndarray
    size_m: tuple[float, float]
    state: str
    markers: tuple[int, ...]
    t_s: float
    moved: bool = False
    reason: str = ""


class BoardTracker:
    """The board pose frame after frame, holding the last good one through short occlusions of the markers."""

    def __init__(self, params: BoardParams) -> None:
        self.p = params
        self.layout = params.layout
        self.detector = make_detector(self.layout)
        self.size_m: tuple[float, float] | None = None if params.size_m == (0.0, 0.0) else params.size_m
        self.last: BoardEstimate | None = None
        self._corners: dict[int, np.ndarray] = {}  # the markers seen in the last frame
        self._windows = make_detector(self.layout)
        self._image_params = self.detector.getDetectorParameters()
        self._window_params = self._windows.getDetectorParameters()
        self.why = ""  # why the last frame gave no fresh pose
        self.markers_left_out = 0  # frames whose pose left out one marker that disagreed with the others

    def update(self, grey: np.ndarray, K: np.ndarray, T_camera_to_world: np.ndarray,
               t_s: float) -> BoardEstimate | None:
        """The board in this frame (``grey`` (H, W) uint8); None until it has been found once."""
        markers = self._detect(grey)
        reason = self._why_not(markers)
        T_bc, size = None, self.size_m
        if not reason:
            try:
                if size is None:
                    size, T_bc, rms = measure_board(markers, K, self.layout)
                else:
                    guess = self.last.T_board_to_camera if self.last is not None else None
                    T_bc, rms = solve_pose(markers, size, K, guess, self.layout)
                    if rms > self.p.max_reprojection_px:
                        fit = solve_pose_without_worst(markers, size, K, guess, self.layout,
                                                       self.p.max_reprojection_px)
                        if fit is not None:  # one marker cut by the arm: the board is where the others put it
                            T_bc, rms, left_out = fit
                            markers = {i: c for i, c in markers.items() if i != left_out}
                            self.markers_left_out += 1
                    if rms > self.p.max_reprojection_px and self.p.size_m == (0.0, 0.0) and len(markers) >= 3:
                        size, T_bc, rms = measure_board(markers, K, self.layout)  # another board, of another size
                if rms > self.p.max_reprojection_px:
                    reason = f"markers reproject badly ({rms:.1f} px RMS)"
            except (ValueError, cv2.error) as exc:
                reason = f"board pose failed: {str(exc).splitlines()[0][:60]}"
        self.why = reason
        if reason:
            return self._hold(markers, t_s, reason)
        assert T_bc is not None and size is not None  # a pose, since there is no reason against it
        T_bw = T_camera_to_world @ T_bc
        moved = False
        if self.last is not None:
            dist, angle = pose_distance(self.last.T_board_to_world, T_bw)
            moved = dist > self.p.moved_m or angle > self.p.moved_deg
        self.size_m = size
        self.last = BoardEstimate(T_bw, T_bc, size, "seen", tuple(sorted(markers)), t_s, moved)
        return self.last

    def _detect(self, grey: np.ndarray) -> dict[int, np.ndarray]:
        """The board's markers in ``grey``: where all four were in the last frame, each is looked for in a window
        around its last corners (:data:`WINDOW_PAD` of its size on every side: a frame at 30 Hz moves a marker
        a few pixels); when one is not found there, or fewer were seen, in the whole image. The detector's
        thresholds are local (windows of at most 23 px) and its corner refinement is local too, so a window
        gives the corners the whole image gives, in a fraction of the pixels."""
        last = self._corners
        if len(last) == len(self.layout.ids):
            found: dict[int, np.ndarray] = {}
            rows, cols = grey.shape[:2]
            for i, c in last.items():
                pad = max(WINDOW_PAD * float(np.ptp(c, axis=0).max()), WINDOW_MIN_PX)
                x0, y0 = (max(int(np.floor(v - pad)), 0) for v in c.min(axis=0))
                x1, y1 = int(np.ceil(c[:, 0].max() + pad)), int(np.ceil(c[:, 1].max() + pad))
                window = grey[y0:min(y1, rows), x0:min(x1, cols)]
                got = detect_markers(self._window_detector(max(rows, cols) / max(window.shape)), window, (i,))
                if i not in got:
                    break
                found[i] = got[i] + np.array([x0, y0], float)
            else:
                self._corners = found
                return found
        self._corners = detect_markers(self.detector, grey, self.layout.ids)
        return self._corners

    def _window_detector(self, scale: float) -> cv2.aruco.ArucoDetector:
        """The detector for a window ``scale`` times smaller than the image: its perimeter limits are rates of
        the image's size, so they are scaled to keep the whole image's limits in pixels (a window's own would
        let every small contour in it be tried as a marker)."""
        params = self._window_params
        params.minMarkerPerimeterRate = self._image_params.minMarkerPerimeterRate * scale
        params.maxMarkerPerimeterRate = self._image_params.maxMarkerPerimeterRate * scale
        self._windows.setDetectorParameters(params)
        return self._windows

    def _why_not(self, markers: dict[int, np.ndarray]) -> str:
        if not markers:
            return "no markers seen"
        need = 3 if self.size_m is None else self.p.min_markers
        if len(markers) < need:
            return f"only markers {sorted(markers)} seen (need {need})"
        return ""

    def _hold(self, markers: dict[int, np.ndarray], t_s: float, reason: str) -> BoardEstimate | None:
        last = self.last
        if last is None:
            return None
        state = "held" if t_s - last.t_s <= self.p.hold_s else "lost"
        if state == "lost":
            reason = f"{reason}; board not seen for {t_s - last.t_s:.1f} s"
        return BoardEstimate(last.T_board_to_world, last.T_board_to_camera, last.size_m, state,
                             tuple(sorted(markers)), last.t_s, False, reason)

    def reset(self) -> None:
        """Forget the board (and its measured size unless configured)."""
        self.last = None
        self._corners = {}
        self.size_m = None if self.p.size_m == (0.0, 0.0) else self.p.size_m
