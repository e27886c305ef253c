"""Parameters of the simulator, one frozen dataclass per concern, read from the ``[sim]`` config table.

Layout of the table (every key optional; the defaults are a vertical
whiteboard in front of the robot, three seeded stains, a D435i-like camera)::

    [sim]
    mode = "lockstep"            # or "realtime"
    seed = 0
    gravity_compensated = false  # act like a robot that adds gravity torques itself
    [sim.board]    preset = "wall" | "table" | "custom"; size_m, origin_m, quat_wxyz, ...
    [sim.contact]  friction, stiffness_n_m, damping_n_s_m
    [sim.dirt]     cell_m, stains (count), stain_size_m, threshold_force_n, rate_per_n_m, stain = [...]
    [sim.camera]   enabled, name, width, height, rate_hz, fx, fy, distance_m, elevation_deg, renderer, ...
    [sim.hand]     script, stiffness_n_m, damping_n_s_m, ... (the operator's hand, for lamps teach)
    [sim.plant]    the simulated arm where it is not the description (sim.plant_params)

Every value is checked in ``__post_init__``; an unknown key or a value out
of range raises :class:`~interfaces.errors.ConfigError` naming the key and
its valid range.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any

from interfaces.errors import ConfigError
from runtime.config import In, check_declared, check_int
from runtime.config import check_range as _range
from runtime.config import check_vector as _vector
from runtime.config import dataclass_from_table as _from_table

from .plant_params import PlantParams

MODES = ("lockstep", "realtime")
BOARD_PRESETS = ("wall", "table", "custom")
RENDERERS = ("analytic", "tiny")


@dataclass(frozen=True)
class BoardParams:
    """The whiteboard: a thin box whose front face is the board frame's z = 0 plane.

    preset ``wall``: vertical, 0.8 x 0.6 m, front face 0.68 m in front of the
    robot (world x), bottom edge 0.25 m high. ``table``: horizontal,
    0.7 x 0.5 m, 0.15 m above the robot base, from 0.30 to 0.80 m in front.
    ``custom``: ``origin_m`` (3,) world position of the board frame's origin
    (a corner), ``quat_wxyz`` (4,) its orientation (x along the width, y
    along the height, z out of the board) and ``size_m`` (2,) width, height.
    """

    preset: str = "wall"
    size_m: tuple[float, float] | None = None
    origin_m: tuple[float, float, float] | None = None
    quat_wxyz: tuple[float, float, float, float] | None = None
    thickness_m: Annotated[float, In(0.005, 0.1)] = 0.02

    def __post_init__(self) -> None:
        s = "sim.board"
        check_declared(self, s)
        if self.preset not in BOARD_PRESETS:
            raise ConfigError(f"[{s}] preset must be one of {BOARD_PRESETS}, got {self.preset!r}")
        if self.preset == "custom" and (self.origin_m is None or self.quat_wxyz is None or self.size_m is None):
            raise ConfigError(f"[{s}] preset = 'custom' needs origin_m, quat_wxyz and size_m")
        if self.preset != "custom" and (self.origin_m is not None or self.quat_wxyz is not None):
            raise ConfigError(f"[{s}] origin_m and quat_wxyz need preset = 'custom' (got preset {self.preset!r})")
        if self.size_m is not None:
            object.__setattr__(self, "size_m", _vector(s, "size_m", self.size_m, 2))
            for v in self.size_m:
                _range(s, "size_m", v, 0.3, 3.0)
        if self.origin_m is not None:
            object.__setattr__(self, "origin_m", _vector(s, "origin_m", self.origin_m, 3))
        if self.quat_wxyz is not None:
            q = _vector(s, "quat_wxyz", self.quat_wxyz, 4)
            norm = math.sqrt(sum(v * v for v in q))
            if abs(norm - 1.0) > 1e-3:
                raise ConfigError(f"[{s}] quat_wxyz must be a unit quaternion, got norm {norm:.4f}")
            object.__setattr__(self, "quat_wxyz", tuple(v / norm for v in q))


@dataclass(frozen=True)
class ContactParams:
    """Felt pad on a whiteboard.

    friction : Coulomb coefficient of felt sliding on a melamine/lacquered
    board (0.3-0.4 is typical). stiffness_n_m, damping_n_s_m : the felt's
    compliance along the normal, per contact point (PyBullet applies them
    at each of the pad's corner contacts: a flat pad is four springs, 8e4
    N/m in all, so 10 N presses about 0.13 mm).
    """

    friction: Annotated[float, In(0.0, 2.0)] = 0.35
    stiffness_n_m: Annotated[float, In(1e3, 1e7)] = 2.0e4
    damping_n_s_m: Annotated[float, In(0.0, 1e5)] = 300.0

    def __post_init__(self) -> None:
        check_declared(self, "sim.contact")


@dataclass(frozen=True)
class DirtParams:
    """Dirt on the board and how the eraser removes it.

    cell_m : grid cell [m] (<= 2 mm). Stains: ``stains`` random ones from the
    seed with their larger extent in ``stain_size_m`` (min, max) [m], kept
    ``margin_m`` from the board edges; or an explicit list ``stain`` of
    tables ``{centre_m = [x, y], size_m = s, aspect = a, angle_deg = t}``
    in the board frame. Removal: a covered cell loses dirt as
    ``d <- d exp(-rate_per_n_m (F - threshold_force_n) ds)`` for a normal
    force F above the threshold and a slide ds [m] of the pad over it,
    applied every ``wipe_every_steps`` physics steps with the slide of that
    interval (at wiping speeds of 0.25 m/s the pad moves 1 mm in 4 ms, half
    a cell, so the removal pattern is unchanged at a quarter of the cost).
    """

    cell_m: Annotated[float, In(0.0005, 0.002)] = 0.002
    stains: int = 3
    stain_size_m: tuple[float, float] = (0.04, 0.08)
    margin_m: Annotated[float, In(0.0, 0.5)] = 0.12
    stain: tuple[Mapping[str, Any], ...] = ()
    threshold_force_n: Annotated[float, In(0.0, 100.0)] = 2.0
    rate_per_n_m: Annotated[float, In(0.0, 1e3)] = 2.0
    max_tilt_deg: Annotated[float, In(0.0, 45.0)] = 10.0
    wipe_every_steps: Annotated[int, In(1, 20)] = 4

    def __post_init__(self) -> None:
        s = "sim.dirt"
        check_declared(self, s)
        check_int(s, "stains", self.stains, 0, 12, what="an integer count")
        lo, hi = _vector(s, "stain_size_m", self.stain_size_m, 2)
        if not 0.01 <= lo <= hi <= 0.3:
            raise ConfigError(f"[{s}] stain_size_m must be (min, max) with 0.01 <= min <= max <= 0.3, "
                              f"got {self.stain_size_m!r}")
        object.__setattr__(self, "stain_size_m", (lo, hi))
        if not isinstance(self.stain, (list, tuple)) or not all(isinstance(t, Mapping) for t in self.stain):
            raise ConfigError(f"[{s}] stain must be a list of tables, got {self.stain!r}")
        object.__setattr__(self, "stain", tuple(self.stain))


@dataclass(frozen=True)
class CameraParams:
    """A fixed RGB camera facing the board, intrinsics like a RealSense D435i colour stream.

    fx, fy, cx, cy [px]: default 615 px focal length at 640 px width
    (scaled with the width), principal point at the centre. The pose is
    ``position_m`` / ``look_at_m`` in the world, or automatic: on the board's
    normal through its centre turned ``azimuth_deg`` towards the board's +x
    and ``elevation_deg`` towards its +y (off the arm's line of sight), at
    the distance that fits the board with ``margin`` (fraction).
    light_direction : (3,) world direction towards the light, or None for
    a light in front of and above the board (``sim.camera.light_towards``).
    renderer : ``analytic`` (the arm drawn as shaded polygons over a board
    image rendered once, ``sim.analytic_camera``) or ``tiny`` (PyBullet's
    TinyRenderer every frame).
    """

    enabled: bool = True
    name: str = "board"
    width: Annotated[int, In(64, 1920)] = 640
    height: Annotated[int, In(48, 1080)] = 480
    rate_hz: Annotated[float, In(0.5, 60.0)] = 10.0
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    position_m: tuple[float, float, float] | None = None
    look_at_m: tuple[float, float, float] | None = None
    elevation_deg: Annotated[float, In(0.0, 70.0)] = 30.0
    azimuth_deg: Annotated[float, In(-70.0, 70.0)] = 20.0
    margin: Annotated[float, In(0.0, 1.0)] = 0.15
    shadow: bool = True
    light_direction: tuple[float, float, float] | None = None
    renderer: str = "analytic"

    def __post_init__(self) -> None:
        s = "sim.camera"
        check_declared(self, s)
        if self.renderer not in RENDERERS:
            raise ConfigError(f"[{s}] renderer must be one of {', '.join(RENDERERS)}, got {self.renderer!r}")
        if not isinstance(self.enabled, bool) or not isinstance(self.shadow, bool):
            raise ConfigError(f"[{s}] enabled and shadow must be true or false")
        if not isinstance(self.name, str) or not re.fullmatch(r"[A-Za-z0-9_\-.]+", self.name):
            raise ConfigError(f"[{s}] name must be letters, digits, '_', '-' or '.', got {self.name!r}")
        scale = self.width / 640.0
        for name, default in (("fx", 615.0 * scale), ("fy", 615.0 * scale),
                              ("cx", self.width / 2.0), ("cy", self.height / 2.0)):
            v = getattr(self, name)
            object.__setattr__(self, name, float(default if v is None else v))
            _range(s, name, getattr(self, name), 1.0, 1e4)
        if (self.position_m is None) != (self.look_at_m is None):
            raise ConfigError(f"[{s}] give both position_m and look_at_m, or neither (automatic pose)")
        if self.position_m is not None:
            position, look_at = _vector(s, "position_m", self.position_m, 3), _vector(s, "look_at_m", self.look_at_m, 3)
            object.__setattr__(self, "position_m", position)
            object.__setattr__(self, "look_at_m", look_at)
            if math.dist(position, look_at) < 0.1:
                raise ConfigError(f"[{s}] position_m and look_at_m must be at least 0.1 m apart")
        if self.light_direction is not None:
            object.__setattr__(self, "light_direction", _vector(s, "light_direction", self.light_direction, 3))


@dataclass(frozen=True)
class HandParams:
    """The operator's hand on the tool, for teaching in the simulator (:mod:`sim.hand`).

    script : a CSV file (``t,x,y,z`` [s, m]: the path the hand leads the pad
    along, world frame; or ``t,fx,fy,fz`` [s, N]: a recorded hand force,
    applied as it is); "" = no hand. The path is followed through a
    spring-damper between the hand and the pad centre, stiffness_n_m [N/m]
    and damping_n_s_m [N s/m] (a firm grip: a person's arm is 0.3-3 kN/m),
    and the hand holds the tool's start orientation through
    stiffness_nm_rad [Nm/rad] and damping_nm_s_rad [Nm s/rad]. The hand's
    force is at most max_force_n [N]. Before the script's first time and
    after its last the hand holds its first and last point.
    """

    script: str = ""
    stiffness_n_m: Annotated[float, In(10.0, 2e4)] = 2000.0
    damping_n_s_m: Annotated[float, In(0.0, 2000.0)] = 120.0
    stiffness_nm_rad: Annotated[float, In(0.0, 500.0)] = 30.0
    damping_nm_s_rad: Annotated[float, In(0.0, 50.0)] = 1.5
    max_force_n: Annotated[float, In(1.0, 300.0)] = 80.0

    def __post_init__(self) -> None:
        check_declared(self, "sim.hand")
        if not isinstance(self.script, str):
            raise ConfigError(f"[sim.hand] script must be a file path (string), got {self.script!r}")


@dataclass(frozen=True)
class SimParams:
    """The whole simulator.

    mode : ``lockstep`` (step only after the command answering the last
    state; deterministic) or ``realtime`` (wall-clock steps, newest command
    held). rate_hz : physics and state rate. stale_limit_s : in real time, a
    command older than this makes the robot brake and hold.
    speed_brake_share : the robot side brakes while a joint moves faster than
    this share of its speed limit, as a robot's safety controller does (0: off).
    late_damping_rad_s : a command applied more than two states after the one
    it answers gets the arm's motion since damped, each joint a mode of this
    frequency on its inertia (:mod:`robot.late_answer`; 0, the default: off).
    gravity_compensated : add gravity torques like the real iiwa's own
    controller does (declared in RobotState.capabilities). start_q_rad :
    start joint positions, or None for an automatic pose facing the board
    centre ``start_standoff_m`` off its surface. max_steps : stop after
    this many steps (0 = run until stopped). The joints' rotor inertia and
    friction are not here: the ``[joints]`` table sets them for the sim and
    the controller alike (:mod:`arm.joint_dynamics`).
    """

    mode: str = "lockstep"
    seed: int = 0
    rate_hz: Annotated[float, In(100.0, 5000.0)] = 1000.0
    stale_limit_s: float = 0.02
    speed_brake_share: Annotated[float, In(0.0, 1.0)] = 0.95
    late_damping_rad_s: Annotated[float, In(0.0, 500.0)] = 0.0
    gravity_compensated: bool = False
    start_q_rad: tuple[float, ...] | None = None
    start_standoff_m: Annotated[float, In(0.01, 0.5)] = 0.08
    truth_rate_hz: float = 10.0
    status_rate_hz: Annotated[float, In(0.1, 100.0)] = 2.0
    lockstep_republish_s: Annotated[float, In(0.001, 10.0)] = 0.1
    lockstep_camera_sync: bool = True
    max_steps: int = 0
    board: BoardParams = field(default_factory=BoardParams)
    contact: ContactParams = field(default_factory=ContactParams)
    dirt: DirtParams = field(default_factory=DirtParams)
    camera: CameraParams = field(default_factory=CameraParams)
    hand: HandParams = field(default_factory=HandParams)
    plant: PlantParams = field(default_factory=PlantParams)

    def __post_init__(self) -> None:
        s = "sim"
        check_declared(self, s)
        if self.mode not in MODES:
            raise ConfigError(f"[{s}] mode must be one of {MODES}, got {self.mode!r}")
        check_int(s, "seed", self.seed, 0)
        _range(s, "stale_limit_s", self.stale_limit_s, 2.0 / self.rate_hz, 1.0)
        for name in ("gravity_compensated", "lockstep_camera_sync"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"[{s}] {name} must be true or false, got {getattr(self, name)!r}")
        if self.start_q_rad is not None:
            object.__setattr__(self, "start_q_rad", _vector(s, "start_q_rad", self.start_q_rad, 7))
        _range(s, "truth_rate_hz", self.truth_rate_hz, 0.1, self.rate_hz)
        check_int(s, "max_steps", self.max_steps, 0)

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> SimParams:
        """The ``[sim]`` table (with its sub-tables) as parameters."""
        table = dict(table)
        if "joint_damping_nm_s_rad" in table:
            raise ConfigError("[sim] joint_damping_nm_s_rad: joint friction is set per joint in the [joints] table "
                              "(viscous_nm_s_rad, coulomb_nm), which the controller's model reads too")
        subs = {"board": BoardParams, "contact": ContactParams, "dirt": DirtParams, "camera": CameraParams,
                "hand": HandParams, "plant": PlantParams}
        parts = {name: _from_table(kind, f"sim.{name}", table.pop(name, {})) for name, kind in subs.items()}
        return _from_table(cls, "sim", table, **parts)
