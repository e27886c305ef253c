"""Parameters of ``lamps perception``, one frozen dataclass per concern, from the ``[perception]`` config table.

Layout (every key optional)::

    [perception]
    camera = "board"            # frames from camera/<camera>/frame
    source = "zenoh"            # or "folder:DIR", "video:FILE", "device:N" (offline checks, a UVC camera)
    publish_rate_hz = 10.0      # perception/stains at least this often
    tool_mask = true            # the robot's tool (from robot/state) is not board: masked out of the image
    tool_margin_m = 0.01        # ... its shadow from the camera on the board grown by this [m]
    tool_max_age_s = 0.1        # ... from the joint state nearest the frame's time, if this near [s]
    device_size_px = [1280, 720]  # device:N asks the camera for this size, rate and pixel format
    device_fps = 30.0
    device_fourcc = "MJPG"
    arm_mask = false            # every link of the arm masked too, grown by the state's age times its speed
    [perception.board]   size_m, resolution_m, min_markers, hold_s, max_reprojection_px, ...
    [perception.ink]     inks, board_rgb, stain_level, clean_level, illumination_range, white_fill_m, ...
    [perception.stains]  link_m, min_area_m2, confirm_s, region_margin_m
    [perception.kappa]   level, debounce_s, min_seen, memory_s, reappear_margin
    [perception.smear]   passes, min_progress, hidden_below, seen_above (perception/smear.py)
    [perception.camera_model]  fx, fy, cx, cy, position_m, look_at_m, up_m (sources without one)

Every value is checked when built; an unknown key or a value out of range
raises :class:`~interfaces.errors.ConfigError` naming the key and its range.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, cast

from interfaces.board_markers import DEFAULT_LAYOUT, MarkerLayout
from interfaces.errors import ConfigError
from runtime.config import In, check_declared, check_vector, dataclass_from_table

from .smear import SmearParams


@dataclass(frozen=True)
class BoardParams:
    """Finding the board.

    size_m : (width, height) [m], or (0, 0) to measure it from the corner
    markers at the first fix. resolution_m : pixel size of the rectified
    board image [m]. min_markers : markers needed for a fresh pose. hold_s :
    the last good pose is used this long when too few markers are seen
    (the arm covers them) [s]; after that the stains are unknown.
    max_reprojection_px : RMS corner reprojection error above which a pose is
    refused. moved_m / moved_deg : a jump this large means another board (or
    a moved one): the stains are detected afresh. edge_margin_m : border of
    the board not looked at (rectification bleeds over its edge) [m].
    dictionary, marker_ids, marker_side_m, marker_inset_m : the corner
    markers (:class:`~interfaces.board_markers.MarkerLayout`): an OpenCV
    ArUco dictionary or AprilTag family by name, the ids at the bottom-left,
    bottom-right, top-right and top-left corners, the side of a marker
    (black border included) [m] and its outer corner's inset from both
    board edges [m]; the defaults are the cell's board. marker_margin_m :
    the band around each marker left out of the stain search (printed
    markers sit on paper whose edge casts a line) [m].
    """

    size_m: tuple[float, float] = (0.0, 0.0)
    resolution_m: Annotated[float, In(0.0005, 0.01)] = 0.002
    min_markers: Annotated[int, In(1, 4)] = 2
    hold_s: Annotated[float, In(0.0, 600.0)] = 2.0
    max_reprojection_px: Annotated[float, In(0.1, 20.0)] = 2.0
    moved_m: Annotated[float, In(0.001, 1.0)] = 0.03
    moved_deg: Annotated[float, In(0.1, 90.0)] = 3.0
    edge_margin_m: Annotated[float, In(0.0, 0.1)] = 0.01
    dictionary: str = DEFAULT_LAYOUT.dictionary
    marker_ids: tuple[int, int, int, int] = DEFAULT_LAYOUT.ids
    marker_side_m: Annotated[float, In(0.005, 1.0)] = DEFAULT_LAYOUT.side_m
    marker_inset_m: Annotated[float, In(0.0, 0.5)] = DEFAULT_LAYOUT.inset_m
    marker_margin_m: Annotated[float, In(0.0, 0.2)] = 0.005

    def __post_init__(self) -> None:
        s = "perception.board"
        check_declared(self, s)
        size = check_vector(s, "size_m", self.size_m, 2)
        object.__setattr__(self, "size_m", size)
        if size != (0.0, 0.0) and not all(0.2 <= v <= 5.0 for v in size):
            raise ConfigError(f"[{s}] size_m must be [0, 0] (measure) or two lengths in [0.2, 5.0] m, got {list(size)}")
        ids = tuple(self.marker_ids) if isinstance(self.marker_ids, (list, tuple)) else self.marker_ids
        try:
            layout = MarkerLayout(self.dictionary, cast(tuple[int, int, int, int], ids), float(self.marker_side_m),
                                  float(self.marker_inset_m))  # MarkerLayout checks the ids
        except (ValueError, TypeError) as exc:
            raise ConfigError(f"[{s}] {exc}") from None
        object.__setattr__(self, "marker_ids", layout.ids)

    @property
    def layout(self) -> MarkerLayout:
        """The corner markers this board carries."""
        return MarkerLayout(self.dictionary, self.marker_ids, self.marker_side_m, self.marker_inset_m)


@dataclass(frozen=True)
class InkParams:
    """Telling ink (of several colours) from clean board and from anything that is not board.

    Each board pixel is explained, relative to the local white (the clean
    board under this frame's light, :mod:`perception.classify`), as ``x = s
    (1 - d a_k)`` per channel: illumination ``s`` (shading, shadows) and
    ink fraction ``d`` of the ink ``k`` that explains it best, with that
    ink's absorption ``a_k = 1 - inks[k] / board_rgb``. inks : name -> the
    ink's colour on the clean board ``board_rgb`` in the same light (RGB,
    0-255); the default is the simulator's blue marker, a real board lists
    its markers (see tests/fixtures/whiteboards/board.toml). stain_level :
    ink fraction from which a pixel is stain. clean_level : ink fraction at
    or below which a pixel counts as clean, the ghost an eraser leaves (a
    stain's remaining ink is what lies above it). illumination_range :
    ``s`` outside it is not board (the arm, deep shadow). max_residual :
    colour distance from the board-and-ink model above which a pixel is not
    board (the eraser, the arm's orange ring); it grows by ``chroma_tolerance``
    times the ink's strength (real inks are not one colour). prior_weight :
    pull of ``s`` towards 1 (needed for neutral, e.g. black, ink).
    white_fill_m : dark features narrower than this (strokes) are filled
    when the local white is measured, wider ones (a shadow, glare's edge)
    are followed [m]. white_follow : the local white stays within this
    factor range of the board-wide fit (a solid stain wider than
    white_fill_m is not taken for a shadow). occlusion_fill_m /
    occlusion_margin_m : occluded areas are closed over gaps narrower than
    the first and grow by the second [m].
    """

    inks: Mapping[str, tuple[float, float, float]] = field(default_factory=lambda: {"blue": (28.0, 38.0, 96.0)})
    board_rgb: tuple[float, float, float] = (242.0, 243.0, 238.0)
    stain_level: Annotated[float, In(0.05, 0.95)] = 0.3
    clean_level: Annotated[float, In(0.0, 0.5)] = 0.05
    illumination_range: tuple[float, float] = (0.82, 1.3)
    max_residual: Annotated[float, In(0.005, 1.0)] = 0.06
    chroma_tolerance: Annotated[float, In(0.0, 1.0)] = 0.0
    prior_weight: Annotated[float, In(0.0, 10.0)] = 0.002
    white_fill_m: Annotated[float, In(0.0, 0.2)] = 0.0
    white_follow: tuple[float, float] = (0.9, 1.1)
    light_step: Annotated[float, In(0.01, 1.0)] = 0.15
    occlusion_min_m: Annotated[float, In(0.0, 0.1)] = 0.0
    occlusion_fill_m: Annotated[float, In(0.0, 0.2)] = 0.04
    occlusion_margin_m: Annotated[float, In(0.0, 0.05)] = 0.004

    def __post_init__(self) -> None:
        s = "perception.ink"
        check_declared(self, s)
        board = check_vector(s, "board_rgb", self.board_rgb, 3)
        if not all(0 < b <= 255 for b in board):
            raise ConfigError(f"[{s}] board_rgb must be a colour in (0, 255], got {list(board)}")
        object.__setattr__(self, "board_rgb", board)
        if not isinstance(self.inks, Mapping) or not 1 <= len(self.inks) <= 8:
            raise ConfigError(f"[{s}] inks must be a table of 1 to 8 named colours, e.g. "
                              "{ blue = [28, 38, 96] }, got " + repr(self.inks))
        inks = {}
        for name, rgb in self.inks.items():
            if not re.fullmatch(r"[a-z][a-z0-9_]{0,15}", str(name)):
                raise ConfigError(f"[{s}] ink name {name!r} must be lower-case letters, digits or '_' "
                                  "(16 at most), starting with a letter")
            ink = check_vector(s, f"inks.{name}", rgb, 3)
            if not all(0 <= v <= 255 for v in ink):
                raise ConfigError(f"[{s}] inks.{name} must be a colour in [0, 255], got {list(ink)}")
            if max(1 - i / b for i, b in zip(ink, board)) < 0.2:
                raise ConfigError(f"[{s}] inks.{name} {list(ink)} must be darker than board_rgb {list(board)} "
                                  "by at least 20 % in some channel")
            inks[str(name)] = ink
        object.__setattr__(self, "inks", inks)
        if self.clean_level >= self.stain_level:
            raise ConfigError(f"[{s}] clean_level {self.clean_level} must be below stain_level {self.stain_level}")
        lo, hi = check_vector(s, "illumination_range", self.illumination_range, 2)
        if not 0.05 <= lo < 1.0 < hi <= 5.0:
            raise ConfigError(f"[{s}] illumination_range must be [lo, hi] with 0.05 <= lo < 1 < hi <= 5, "
                              f"got {[lo, hi]}")
        object.__setattr__(self, "illumination_range", (lo, hi))
        lo, hi = check_vector(s, "white_follow", self.white_follow, 2)
        if not 0.2 <= lo <= 1.0 <= hi <= 5.0:
            raise ConfigError(f"[{s}] white_follow must be [lo, hi] with 0.2 <= lo <= 1 <= hi <= 5, got {[lo, hi]}")
        object.__setattr__(self, "white_follow", (lo, hi))

    @property
    def ink_names(self) -> tuple[str, ...]:
        return tuple(self.inks)


@dataclass(frozen=True)
class StainParams:
    """Clustering stain pixels into stains and following them.

    link_m : stain pixels closer than this belong to the same stain
    (single-linkage clustering, the number of stains is not given) [m].
    min_area_m2 : smaller clusters are noise [m^2]. confirm_s : a new
    cluster becomes a stain after it has been seen this long [s] (and
    perception/stains is first published once the board has been watched
    this long). region_margin_m : a stain's region reaches this far beyond
    its ink, so its edges count in the remaining fraction [m].
    """

    link_m: Annotated[float, In(0.001, 0.2)] = 0.015
    min_area_m2: Annotated[float, In(1e-6, 0.1)] = 1.5e-4
    confirm_s: Annotated[float, In(0.0, 10.0)] = 0.3
    region_margin_m: Annotated[float, In(0.0, 0.05)] = 0.006

    def __post_init__(self) -> None:
        s = "perception.stains"
        check_declared(self, s)


@dataclass(frozen=True)
class KappaParams:
    """When a stain counts as wiped (kappa = 1).

    kappa turns 1 once the remaining fraction has stayed at or below
    ``level`` for ``debounce_s`` while at least ``min_seen`` of the stain has
    been seen within the last ``memory_s`` (an occluded pixel keeps its last
    observation and never counts as clean by being hidden). It returns to 0
    only when the remaining fraction rises above ``level + reappear_margin``
    for ``debounce_s`` (new ink on the stain).
    """

    level: Annotated[float, In(0.0, 0.9)] = 0.03
    debounce_s: Annotated[float, In(0.0, 10.0)] = 0.2
    min_seen: Annotated[float, In(0.1, 1.0)] = 0.9
    memory_s: Annotated[float, In(0.05, 60.0)] = 1.5
    reappear_margin: Annotated[float, In(0.01, 1.0)] = 0.1

    def __post_init__(self) -> None:
        s = "perception.kappa"
        check_declared(self, s)


@dataclass(frozen=True)
class CameraModelParams:
    """The camera model for sources whose frames carry none (image folder, video file, capture device).

    fx, fy, cx, cy [px] at the frames' resolution (0 = a D435i-like 615 px
    focal length scaled to the width, principal point at the centre), or
    calibration: a ROS ``camera_info`` YAML or an OpenCV calibration file
    (:mod:`perception.calibration`: intrinsics and lens distortion, scaled to
    the frames; each frame is undistorted before anything looks at it);
    position_m, look_at_m, up_m: the camera pose in the world (robot base)
    frame; the board pose is then reported in that frame.
    """

    fx: Annotated[float, In(0.0, 20000.0)] = 0.0
    fy: Annotated[float, In(0.0, 20000.0)] = 0.0
    cx: Annotated[float, In(0.0, 20000.0)] = 0.0
    cy: Annotated[float, In(0.0, 20000.0)] = 0.0
    position_m: tuple[float, float, float] = (0.0, 0.0, 1.0)
    look_at_m: tuple[float, float, float] = (1.0, 0.0, 1.0)
    up_m: tuple[float, float, float] = (0.0, 0.0, 1.0)
    calibration: str = ""

    def __post_init__(self) -> None:
        s = "perception.camera_model"
        check_declared(self, s)
        if not isinstance(self.calibration, str):
            raise ConfigError(f"[{s}] calibration must be a file name, got {self.calibration!r}")
        if self.calibration and any((self.fx, self.fy, self.cx, self.cy)):
            raise ConfigError(f"[{s}] give calibration or fx, fy, cx, cy, not both")
        for name in ("position_m", "look_at_m", "up_m"):
            object.__setattr__(self, name, check_vector(s, name, getattr(self, name), 3))


#: Source specifications: ``zenoh``, ``folder:DIR``, ``video:FILE``, ``device:N``.
SOURCE_KINDS = ("zenoh", "folder", "video", "device")


def parse_source(spec: str) -> tuple[str, str]:
    """``(kind, argument)`` of a source specification, or ConfigError naming the valid forms."""
    if not isinstance(spec, str):
        raise ConfigError(f"[perception] source must be a string, got {spec!r}")
    kind, _, arg = spec.partition(":")
    if kind == "zenoh" and not arg:
        return kind, ""
    if kind in ("folder", "video") and arg:
        return kind, arg
    if kind == "device" and re.fullmatch(r"\d{1,3}|/dev/[A-Za-z0-9_./-]{1,100}", arg):
        return kind, arg
    if kind == "ros" and re.fullmatch(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", arg):
        return kind, arg
    raise ConfigError(f"[perception] source must be 'zenoh', 'folder:DIR', 'video:FILE', 'device:N' (or "
                      f"'device:/dev/videoN') or 'ros:TOPIC' "
                      f"(a ROS 2 image topic through zenoh-bridge-ros2dds), got {spec!r}")


@dataclass(frozen=True)
class PerceptionParams:
    """Everything ``lamps perception`` needs (see the module docstring for the layout)."""

    camera: str = "board"
    source: str = "zenoh"
    publish_rate_hz: Annotated[float, In(1.0, 200.0)] = 10.0
    status_rate_hz: Annotated[float, In(0.1, 50.0)] = 2.0
    debug_images: bool = False
    debug_rate_hz: Annotated[float, In(0.1, 30.0)] = 2.0
    frame_timeout_s: Annotated[float, In(0.1, 60.0)] = 2.0
    source_rate_hz: Annotated[float, In(0.1, 120.0)] = 10.0
    device_size_px: tuple[int, int] = (1280, 720)
    device_fps: Annotated[float, In(1.0, 240.0)] = 30.0
    device_fourcc: str = "MJPG"
    tool_mask: bool = True
    tool_margin_m: Annotated[float, In(0.0, 0.1)] = 0.01
    tool_max_age_s: Annotated[float, In(0.001, 5.0)] = 0.1
    arm_mask: bool = False
    board: BoardParams = field(default_factory=BoardParams)
    ink: InkParams = field(default_factory=InkParams)
    stains: StainParams = field(default_factory=StainParams)
    kappa: KappaParams = field(default_factory=KappaParams)
    model: CameraModelParams = field(default_factory=CameraModelParams)
    smear: SmearParams = field(default_factory=SmearParams)

    def __post_init__(self) -> None:
        s = "perception"
        check_declared(self, s)
        if not isinstance(self.camera, str) or not re.fullmatch(r"[A-Za-z0-9_\-.]+", self.camera):
            raise ConfigError(f"[{s}] camera must be letters, digits, '_', '-' or '.', got {self.camera!r}")
        parse_source(self.source)
        size = check_vector(s, "device_size_px", self.device_size_px, 2)
        if not all(float(v).is_integer() and 16 <= v <= 8192 for v in size):
            raise ConfigError(f"[{s}] device_size_px must be [width, height] in whole pixels, 16-8192, "
                              f"got {self.device_size_px!r}")
        object.__setattr__(self, "device_size_px", (int(size[0]), int(size[1])))
        if not isinstance(self.device_fourcc, str) or not re.fullmatch(r"([A-Za-z0-9 ]{4})?", self.device_fourcc):
            raise ConfigError(f"[{s}] device_fourcc must be four letters or digits (MJPG, YUYV) or \"\" for the "
                              f"driver's own, got {self.device_fourcc!r}")
        if not isinstance(self.debug_images, bool):
            raise ConfigError(f"[{s}] debug_images must be true or false, got {self.debug_images!r}")
        if not isinstance(self.tool_mask, bool):
            raise ConfigError(f"[{s}] tool_mask must be true or false, got {self.tool_mask!r}")
        if not isinstance(self.arm_mask, bool):
            raise ConfigError(f"[{s}] arm_mask must be true or false, got {self.arm_mask!r}")

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> PerceptionParams:
        """The ``[perception]`` table (with its sub-tables) as parameters."""
        if not isinstance(table, Mapping):
            raise ConfigError(f"[perception] must be a table, got {type(table).__name__}")
        table = dict(table)
        subs = {"board": BoardParams, "ink": InkParams, "stains": StainParams, "kappa": KappaParams,
                "camera_model": CameraModelParams, "smear": SmearParams}
        parts = {}
        for name, kind in subs.items():
            key = "model" if name == "camera_model" else name
            try:
                parts[key] = dataclass_from_table(kind, f"perception.{name}", table.pop(name, {}))
            except TypeError as exc:
                raise ConfigError(f"[perception.{name}] {exc}") from None
        return dataclass_from_table(cls, "perception", table, **parts)
