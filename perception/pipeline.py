"""One camera frame in, the board and its stains out: the whole of perception without any I/O.

:meth:`Perception.process` runs board finding (:mod:`~perception.board`),
rectification (:mod:`~perception.rectify`), the robot's tool masked out
(:mod:`~perception.self_filter`, when its pose is given), pixel classification
(:mod:`~perception.classify`) and stain tracking (:mod:`~perception.tracking`)
and returns a :class:`Result` whose ``stains`` is the message to publish (or
None while nothing can be said yet) and whose ``reason`` says why a frame
did not give a fresh view.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from interfaces.messages import StainObservation, Stains
from interfaces.transforms import pose_from_transform

from .arm_mask import ArmSilhouette
from .board import BoardEstimate, BoardTracker
from .classify import InkClassifier, InkMap
from .frames import Frame
from .params import PerceptionParams
from .rectify import BoardGrid
from .self_filter import ArmState, board_shadow, pad_footprint, shadow_mask
from .smear import SmearWatch, pad_over
from .tracking import StainTracker

#: The frame clock going back by more than this means a restarted source [s].
CLOCK_RESTART_S = 1.0


@dataclass
class Result:
    """What one frame gave.

    stains : the message to publish, or None (board never found, warming
    up). board : the board estimate (None before the first fix). reason :
    why the view is not fresh ("" when it is). timing_ms : duration of
    each stage. ink / rect : this frame's classification and rectified image
    (None when the board is lost), for debug images.
    """

    stains: Stains | None
    board: BoardEstimate | None
    reason: str = ""
    timing_ms: dict[str, float] = field(default_factory=dict)
    ink: InkMap | None = None
    rect: np.ndarray | None = None


class Perception:
    """Board, stains and kappa from a stream of :class:`~perception.frames.Frame`."""

    def __init__(self, params: PerceptionParams) -> None:
        self.p = params
        self.board = BoardTracker(params.board)
        self.grid: BoardGrid | None = None
        self.classifier: InkClassifier | None = None
        self.tracker: StainTracker | None = None
        self.smear = SmearWatch(params.smear)
        self._first_fix_t: float | None = None
        self._last_t: float | None = None
        self._seq = 0
        self.resets = 0
        self.arm_silhouette: ArmSilhouette | None = None  # made at the first frame with an arm state
        self._pad_known = False  # this frame's tool pose was given: _pad is where the pad wipes (None: nowhere)
        self._pad: tuple[np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the board and its stains (a restarted source, another board)."""
        self.board.reset()
        self.grid = self.classifier = self.tracker = None
        self.smear = SmearWatch(self.p.smear)
        self._first_fix_t = None
        self.resets += 1

    def process(self, frame: Frame, tool_world_m: np.ndarray | None = None, arm: ArmState | None = None) -> Result:
        """The board and its stains in ``frame``; ``tool_world_m`` (n, 3) [m]: the robot's tool box at the
        frame's time (:mod:`perception.self_filter`), whose shadow from the camera on the board is occluded;
        ``arm``: the joint state nearest the frame, whose every link's shadow is occluded
        (:mod:`perception.arm_mask`)."""
        timing: dict[str, float] = {}
        t0 = time.perf_counter()
        if self._last_t is not None and frame.t_s < self._last_t - CLOCK_RESTART_S:
            self.reset()
        self._last_t = frame.t_s
        grey = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2GRAY)
        est = self.board.update(grey, frame.K, frame.T_camera_to_world, frame.t_s)
        t1 = time.perf_counter()
        timing["board"] = (t1 - t0) * 1e3
        if est is None:
            return Result(None, None, "board not found: " + self.board.why, timing)
        if est.moved or (self.grid is not None and self.grid.size_m != est.size_m):
            self.reset()
            self.board.last = est  # keep this fix: it is the new board
            self.board.size_m = est.size_m
        if self.grid is None:
            self._setup(est)
        grid, classifier, tracker = self.grid, self.classifier, self.tracker
        assert grid is not None and classifier is not None and tracker is not None  # made together by _setup
        if self._first_fix_t is None:
            self._first_fix_t = frame.t_s
        if est.state == "lost":
            return Result(self._message(est, frame, lost=True), est, est.reason, timing)
        rect = grid.warp(frame.rgb, grid.image_from_grid(frame.K, est.T_board_to_camera))
        t2 = time.perf_counter()
        hidden = None
        self._pad_known = tool_world_m is not None
        self._pad = None if tool_world_m is None else pad_footprint(tool_world_m, est.T_board_to_world)
        if tool_world_m is not None:
            camera = frame.T_camera_to_world[:3, 3]
            hidden = shadow_mask(grid, board_shadow(tool_world_m, est.T_board_to_world, camera),
                                 self.p.tool_margin_m)
        if arm is not None:
            if self.arm_silhouette is None:
                self.arm_silhouette = ArmSilhouette()
            links = self.arm_silhouette.board_mask(grid, est.T_board_to_world, frame.T_camera_to_world[:3, 3],
                                                   arm, self.p.tool_margin_m)
            hidden = links if hidden is None else hidden | links
        if tool_world_m is not None or arm is not None:
            t_mask = time.perf_counter()
            timing["mask"] = (t_mask - t2) * 1e3
            t2 = t_mask
        ink = classifier.classify(rect, hidden)
        t3 = time.perf_counter()
        tracker.update(ink, frame.t_s)
        t4 = time.perf_counter()
        timing.update(rectify=(t2 - t1) * 1e3 - timing.get("mask", 0.0), classify=(t3 - t2) * 1e3,
                      track=(t4 - t3) * 1e3)
        warming = frame.t_s - self._first_fix_t < self.p.stains.confirm_s - 1e-9
        msg = None if warming else self._message(est, frame, lost=False)
        reason = est.reason or ("warming up" if warming else "")
        return Result(msg, est, reason, timing, ink, rect)

    def _setup(self, est: BoardEstimate) -> None:
        self.grid = BoardGrid(est.size_m, self.p.board.resolution_m)
        looked_at = self.grid.looked_at(self.p.board.edge_margin_m, self.p.board.marker_margin_m, self.p.board.layout)
        self.classifier = InkClassifier(self.p.ink, looked_at, self.p.board.resolution_m)
        self.tracker = StainTracker(self.grid, self.p.stains, self.p.kappa, self.p.ink.stain_level,
                                    self.p.ink.clean_level)

    def _message(self, est: BoardEstimate, frame: Frame, lost: bool) -> Stains:
        T = est.T_board_to_world
        out = []
        assert self.tracker is not None  # made with the grid, before any message
        for tr in self.tracker.tracks:
            if tr.shape is None:
                continue
            c = tr.shape.centre_m
            world = T[:3, :3] @ np.array([c[0], c[1], 0.0]) + T[:3, 3]
            ink = tr.ink
            visible, kappa = (0.0, False) if lost else (float(tr.visible), bool(tr.kappa))
            on_it = pad_over(self._pad, c, 0.5 * tr.shape.size_m) if self._pad_known else None
            smeared = not lost and self.smear.update(tr.id, float(tr.remaining), visible, kappa, on_it) is not None
            out.append(StainObservation(
                id=tr.id, centre_board_m=[float(c[0]), float(c[1])], centre_world_m=world.tolist(),
                size_m=float(tr.shape.size_m), extent_board_m=[float(v) for v in tr.shape.extent_m],
                remaining=float(tr.remaining), visible=visible, kappa=kappa, width_m=float(tr.shape.width_m),
                axis_board_rad=float(tr.shape.axis_rad),
                ink_centre_board_m=[] if ink is None else [float(ink.centre_m[0]), float(ink.centre_m[1])],
                ink_size_m=0.0 if ink is None else float(ink.size_m),
                ink_width_m=0.0 if ink is None else float(ink.width_m),
                ink_axis_board_rad=0.0 if ink is None else float(ink.axis_rad),
                colour=self.p.ink.ink_names[tr.colour], smeared=smeared, passes=self.smear.passes(tr.id)))
        self._seq += 1
        return Stains(seq=self._seq, stamp_ns=time.monotonic_ns(), T_board_to_world=pose_from_transform(T),
                      board_size_m=[float(v) for v in est.size_m], stains=out, board=est.state,
                      frame_seq=frame.seq, robot_time_ns=frame.robot_time_ns,
                      camera_world_m=[float(v) for v in frame.T_camera_to_world[:3, 3]])
