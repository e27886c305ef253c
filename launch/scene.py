"""What Foxglove's 3D and Image panels draw of the cell, from the cell's own messages (pure, no I/O).

:class:`SceneBuilder` turns robot states, stains and camera frames into
Foxglove's typed messages (``foxglove-sdk``: protobuf with their schemas),
written by the recorder into the MCAP file and served live by
``lamps foxglove``:

* ``<prefix>/scene/tf`` (``foxglove.FrameTransforms``, every
  :data:`TF_PERIOD_S` of robot time): ``world`` (the robot base) to each
  link of the arm (forward kinematics of the URDF with Pinocchio), to the
  pad (``tcp``), to the board and to each camera (its optical frame,
  ``camera_<name>``: :func:`camera_frame_id`);
* ``<prefix>/scene/robot`` (``foxglove.SceneUpdate``): the arm's visual
  geometry from the URDF (cylinders, boxes, spheres in their link frames,
  frame-locked, so the transforms move them), re-sent every
  :data:`STATIC_PERIOD_S` for a viewer that joins late;
* ``<prefix>/scene/board`` (``foxglove.SceneUpdate``): the board and each
  stain as perception reports it, an ellipse of its extent on the board,
  red while ink remains, green once kappa is set, with its id, remaining
  ink and kappa as text;
* ``<camera key>/calibration`` (``foxglove.CameraCalibration``) and
  ``<camera key>/annotations`` (``foxglove.ImageAnnotations``: each stain's
  outline and label projected into that camera's image).

Frames: ``world`` is the robot base frame of ``interfaces/transforms.py``;
the board frame has its origin at a corner, x along the width, y along the
height, z out of the board; camera frames are optical (x right, y down, z
forward). Units: metres, radians. Timestamps are when the message was
received (the recording's log time, the live view's now), so Foxglove finds
every transform, shape and image on one clock; the robot's own clock stays
in the cell's messages.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from foxglove import messages as fm

from arm.description import TCP_FRAME, URDF_PATH, urdf_attr
from interfaces.keys import Keys
from interfaces.messages import CameraFrame, RobotState, Stains

#: Transforms at most this often [s of robot time] (50 Hz: smooth to the eye, 20x less than the 1 kHz states).
TF_PERIOD_S = 0.02
#: The static geometry (the arm's shapes, the calibration) re-sent this often [s], for late viewers.
STATIC_PERIOD_S = 2.0
WORLD = "world"
BOARD = "board"
PAD = "tcp"
#: Points of a stain's outline (an ellipse of its extent) on the board and in the image.
OUTLINE_POINTS = 32

_RED = (0.85, 0.1, 0.1)  # a stain with ink left (rgb)
_GREEN = (0.1, 0.7, 0.2)  # a stain perception judges clean (kappa)
_BOARD_WHITE = fm.Color(r=0.95, g=0.95, b=0.95, a=0.6)


def _colour(rgb: tuple[float, float, float], a: float = 0.8) -> fm.Color:
    return fm.Color(r=rgb[0], g=rgb[1], b=rgb[2], a=a)


def cell_frames(keys: Keys) -> str:
    """The frame-id prefix of a cell in a view of several: its robot id and a slash (``iiwa-1/``; a key prefix of
    its own, whole)."""
    return keys.prefix.removeprefix("lamps/") + "/"


def cells_of(keys) -> list[Keys]:
    """The cells a recorder or live view follows: ``keys`` (one cell's :class:`Keys`) or a sequence of them, each
    once; ValueError otherwise."""
    cells = [keys] if isinstance(keys, Keys) else list(keys)
    if not cells or len({k.prefix for k in cells}) != len(cells):
        raise ValueError(f"one or more cells, each once, are needed; got {[k.prefix for k in cells]}")
    return cells


def scenes_of(cells: list[Keys]) -> dict[str, SceneBuilder]:
    """A :class:`SceneBuilder` per cell by key prefix; with several cells each in its own frame tree."""
    site = len(cells) > 1
    return {k.prefix: SceneBuilder(k, frames=cell_frames(k) if site else "") for k in cells}


def cell_of_key(cells: list[Keys], key: str) -> Keys | None:
    """The cell whose prefix ``key`` is under, or None."""
    return next((k for k in cells if key.startswith(k.prefix + "/")), None)


def camera_frame_id(camera: str) -> str:
    """The frame of camera ``camera`` (its optical frame) in the scene and on its images."""
    return f"camera_{camera}"


def _stamp(t_ns: int) -> fm.Timestamp:
    return fm.Timestamp(sec=int(t_ns // 10**9), nsec=int(t_ns % 10**9))


def _quat_xyzw(R: np.ndarray) -> fm.Quaternion:
    q = pin.Quaternion(np.asarray(R, float))  # x, y, z, w
    return fm.Quaternion(x=float(q.x), y=float(q.y), z=float(q.z), w=float(q.w))


def _pose(p, R) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])), orientation=_quat_xyzw(R))


def _rpy(rpy: list[str]) -> np.ndarray:
    return pin.rpy.rpyToMatrix(*[float(v) for v in rpy])


def _rgba(col: ET.Element | None) -> tuple[float, float, float, float]:
    """The colour of a ``<color>`` element (grey without one)."""
    if col is None:
        return (0.6, 0.6, 0.6, 1.0)
    r, g, b, a = (float(v) for v in urdf_attr(col, "rgba").split())
    return r, g, b, a


def _pose_matrix(pose) -> tuple[np.ndarray, np.ndarray]:
    """(p (3,), R (3, 3)) of an ``interfaces.messages.Pose`` (position, quaternion w, x, y, z)."""
    p = np.asarray(pose.position_m, float)
    w, x, y, z = (float(v) for v in pose.quat_wxyz)
    return p, pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()


@dataclass(frozen=True)
class Visual:
    """One visual shape of a link: pose in the link frame, kind, size [m] (Foxglove's x, y, z extents), colour."""

    link: str
    p: np.ndarray
    R: np.ndarray
    kind: str  # "cylinder" | "cube" | "sphere"
    size: tuple[float, float, float]
    rgba: tuple[float, float, float, float]


def urdf_visuals(urdf_path: str | Path = URDF_PATH) -> list[Visual]:
    """Every ``<visual>`` primitive of the URDF (meshes are skipped: the arm's description has none)."""
    root = ET.parse(str(urdf_path)).getroot()
    colours = {m.get("name"): m.find("color") for m in root.findall("material")}
    out = []
    for link in root.findall("link"):
        for vis in link.findall("visual"):
            origin = vis.find("origin")
            p = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
            R = _rpy((origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split())
            geom = vis.find("geometry")
            mat = vis.find("material")
            col = mat.find("color") if mat is not None and mat.find("color") is not None else \
                colours.get(mat.get("name")) if mat is not None else None
            rgba, name = _rgba(col), urdf_attr(link, "name")
            if geom is None:
                raise ValueError(f"the robot description's link {name!r} has a <visual> without <geometry>")
            for shape in geom:
                if shape.tag == "cylinder":
                    r, h = float(urdf_attr(shape, "radius")), float(urdf_attr(shape, "length"))
                    out.append(Visual(name, p, R, "cylinder", (2 * r, 2 * r, h), rgba))
                elif shape.tag == "box":
                    sx, sy, sz = (float(v) for v in urdf_attr(shape, "size").split())
                    out.append(Visual(name, p, R, "cube", (sx, sy, sz), rgba))
                elif shape.tag == "sphere":
                    d = 2 * float(urdf_attr(shape, "radius"))
                    out.append(Visual(name, p, R, "sphere", (d, d, d), rgba))
    return out


def ellipse_on_board(centre_board_m, extent_board_m, n: int = OUTLINE_POINTS) -> np.ndarray:
    """(n, 3) points of the ellipse with the stain's extents (full widths along board x, y) in the board frame."""
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    cx, cy = (float(v) for v in centre_board_m)
    ex, ey = (max(float(v), 1e-3) / 2 for v in extent_board_m)
    return np.column_stack([cx + ex * np.cos(a), cy + ey * np.sin(a), np.zeros(n)])


def project(points_world: np.ndarray, frame: CameraFrame) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (n, 2) of world points (n, 3) in ``frame``'s camera, and which are in front of it (n,)."""
    p, R = _pose_matrix(frame.T_camera_to_world)
    cam = (np.asarray(points_world, float) - p) @ R  # R^T (x - p), row-wise
    k = frame.intrinsics
    z = np.where(cam[:, 2] > 1e-6, cam[:, 2], np.nan)
    uv = np.column_stack([k.fx * cam[:, 0] / z + k.cx, k.fy * cam[:, 1] / z + k.cy])
    return uv, np.isfinite(z)


class SceneBuilder:
    """Feed each decoded message with :meth:`on_message`; it returns the scene messages due, as (topic, message).

    One instance per consumer (it keeps Pinocchio scratch data, the last board
    and the cameras seen, and when each output was last sent). ``frames`` is put
    before every frame id it names (``world`` becomes ``iiwa-1/world``): a view of
    several cells gives each its own tree (:func:`cell_frames`); "" for one cell.
    """

    def __init__(self, keys: Keys, urdf_path: str | Path = URDF_PATH, frames: str = "") -> None:
        self.keys = keys
        self.frames = frames
        self.world = frames + WORLD
        self.model = pin.buildModelFromUrdf(str(urdf_path))
        self.data = self.model.createData()
        self.links = [f.name for f in self.model.frames if f.type == pin.FrameType.BODY]
        self._link_ids = [self.model.getFrameId(n) for n in self.links]
        self._tcp_id = self.model.getFrameId(TCP_FRAME)
        self.visuals = [v for v in urdf_visuals(urdf_path) if v.link in self.links]
        self.topic_tf = f"{keys.prefix}/scene/tf"
        self.topic_robot = f"{keys.prefix}/scene/robot"
        self.topic_board = f"{keys.prefix}/scene/board"
        self._last_tf_ns: int | None = None
        self._last_static_ns: dict[str, int] = {}
        self._cameras: dict[str, CameraFrame] = {}  # camera key -> its newest frame (pose, intrinsics)

    # -------------------------------------------------------------------------------------------- dispatch

    def on_message(self, key: str, msg, t_ns: int) -> list[tuple[str, fm.FoxgloveMessage]]:
        """The scene messages ``msg`` (received on ``key`` at wall time ``t_ns``) makes due."""
        if isinstance(msg, RobotState):
            return self._on_state(msg, t_ns)
        if isinstance(msg, Stains):
            return self._on_stains(msg, t_ns)
        if isinstance(msg, CameraFrame):
            return self._on_frame(key, msg, t_ns)
        return []

    def _due(self, what: str, t_ns: int) -> bool:
        last = self._last_static_ns.get(what)
        if last is None or t_ns - last >= STATIC_PERIOD_S * 1e9 or t_ns < last:
            self._last_static_ns[what] = t_ns
            return True
        return False

    # -------------------------------------------------------------------------------------------- the arm

    def _on_state(self, st: RobotState, t_ns: int) -> list:
        robot_ns = st.robot_time_ns or st.stamp_ns  # thinned on the robot's clock (a lock-step cell runs faster)
        if self._last_tf_ns is not None and 0 <= robot_ns - self._last_tf_ns < TF_PERIOD_S * 1e9:
            return []
        self._last_tf_ns = robot_ns
        out: list[tuple[str, Any]] = [(self.topic_tf, self.arm_transforms(np.asarray(st.q_rad, float), t_ns))]
        if self._due("robot", t_ns):
            out.append((self.topic_robot, self.arm_geometry(t_ns)))
        return out

    def arm_transforms(self, q: np.ndarray, t_ns: int) -> fm.FrameTransforms:
        """``world`` -> each link and the pad at joint positions ``q`` (7,) [rad]."""
        pin.framesForwardKinematics(self.model, self.data, q)
        stamp = _stamp(t_ns)
        tfs = []
        for name, fid in [*zip(self.links, self._link_ids), (PAD, self._tcp_id)]:
            oMf = self.data.oMf[fid]
            p = oMf.translation
            tfs.append(fm.FrameTransform(timestamp=stamp, parent_frame_id=self.world, child_frame_id=self.frames + name,
                                         translation=fm.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                                         rotation=_quat_xyzw(oMf.rotation)))
        return fm.FrameTransforms(transforms=tfs)

    def arm_geometry(self, t_ns: int) -> fm.SceneUpdate:
        """The URDF's visual shapes, each in its link frame (frame-locked: the transforms move them)."""
        stamp = _stamp(t_ns)
        by_link: dict[str, dict[str, list]] = {}
        for v in self.visuals:
            col = fm.Color(r=v.rgba[0], g=v.rgba[1], b=v.rgba[2], a=v.rgba[3])
            size = fm.Vector3(x=v.size[0], y=v.size[1], z=v.size[2])
            prims = by_link.setdefault(v.link, {"cylinders": [], "cubes": [], "spheres": []})
            if v.kind == "cylinder":
                prims["cylinders"].append(fm.CylinderPrimitive(pose=_pose(v.p, v.R), size=size, bottom_scale=1.0,
                                                               top_scale=1.0, color=col))
            elif v.kind == "cube":
                prims["cubes"].append(fm.CubePrimitive(pose=_pose(v.p, v.R), size=size, color=col))
            else:
                prims["spheres"].append(fm.SpherePrimitive(pose=_pose(v.p, v.R), size=size, color=col))
        entities = [fm.SceneEntity(timestamp=stamp, frame_id=self.frames + link, id=f"robot/{link}", frame_locked=True,
                                   cylinders=prims["cylinders"], cubes=prims["cubes"], spheres=prims["spheres"])
                    for link, prims in by_link.items()]
        return fm.SceneUpdate(entities=entities)

    # ------------------------------------------------------------------------------------ board and stains

    def _on_stains(self, s: Stains, t_ns: int) -> list:
        out = [(self.topic_tf, self.board_transform(s, t_ns)), (self.topic_board, self.board_scene(s, t_ns))]
        for key, frame in self._cameras.items():
            out.append((f"{key}/annotations", self.image_annotations(s, frame, t_ns)))
        return out

    def board_transform(self, s: Stains, t_ns: int) -> fm.FrameTransforms:
        p, R = _pose_matrix(s.T_board_to_world)
        return fm.FrameTransforms(transforms=[fm.FrameTransform(
            timestamp=_stamp(t_ns), parent_frame_id=self.world, child_frame_id=self.frames + BOARD,
            translation=fm.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])), rotation=_quat_xyzw(R))])

    def board_scene(self, s: Stains, t_ns: int) -> fm.SceneUpdate:
        """The board (a thin plate behind its surface) and each stain on it, replacing what was there."""
        stamp = _stamp(t_ns)
        w, h = (float(v) for v in s.board_size_m)
        eye = np.eye(3)
        board = fm.SceneEntity(
            timestamp=stamp, frame_id=self.frames + BOARD, id="board", frame_locked=True,
            cubes=[fm.CubePrimitive(pose=_pose((w / 2, h / 2, -0.003), eye), size=fm.Vector3(x=w, y=h, z=0.006),
                                    color=_BOARD_WHITE)],
            texts=[fm.TextPrimitive(pose=_pose((0.0, h + 0.03, 0.0), eye), billboard=True, font_size=14.0,
                                    scale_invariant=True, color=fm.Color(r=1, g=1, b=1, a=1),
                                    text=f"board {s.board}: {sum(x.kappa for x in s.stains)}/{len(s.stains)} clean")])
        entities = [board]
        for st in s.stains:
            rgb = _GREEN if st.kappa else _RED
            colour = _colour(rgb)
            ring = ellipse_on_board(st.centre_board_m, st.extent_board_m)
            pts = [fm.Point3(x=float(x), y=float(y), z=0.002) for x, y, _ in ring]
            entities.append(fm.SceneEntity(
                timestamp=stamp, frame_id=self.frames + BOARD, id=f"stain/{st.id}", frame_locked=True,
                lines=[fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineLoop, pose=_pose((0, 0, 0), eye),
                                        thickness=4.0, scale_invariant=True, points=pts, color=colour)],
                cylinders=[fm.CylinderPrimitive(
                    pose=_pose((st.centre_board_m[0], st.centre_board_m[1], 0.001), eye),
                    size=fm.Vector3(x=max(st.extent_board_m[0], 1e-3), y=max(st.extent_board_m[1], 1e-3), z=0.002),
                    bottom_scale=1.0, top_scale=1.0,
                    color=_colour(rgb, 0.25 + 0.5 * st.remaining))],
                texts=[fm.TextPrimitive(pose=_pose((st.centre_board_m[0], st.centre_board_m[1], 0.02), eye),
                                        billboard=True, font_size=12.0, scale_invariant=True, color=colour,
                                        text=f"{st.id}: {st.remaining:.0%}" + (" kappa" if st.kappa else ""))]))
        # everything before is replaced: a stain perception no longer reports disappears
        return fm.SceneUpdate(deletions=[fm.SceneEntityDeletion(timestamp=stamp,
                                                                type=fm.SceneEntityDeletionType.All, id="")],
                              entities=entities)

    # ------------------------------------------------------------------------------------------- cameras

    def _on_frame(self, key: str, f: CameraFrame, t_ns: int) -> list:
        self._cameras[key] = f
        p, R = _pose_matrix(f.T_camera_to_world)
        out: list[tuple[str, Any]] = [(self.topic_tf, fm.FrameTransforms(transforms=[fm.FrameTransform(
            timestamp=_stamp(t_ns), parent_frame_id=self.world, child_frame_id=self.frames + camera_frame_id(f.camera),
            translation=fm.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])), rotation=_quat_xyzw(R))]))]
        out.append((f"{key}/calibration", self.calibration(f, t_ns)))
        return out

    def calibration(self, f: CameraFrame, t_ns: int) -> fm.CameraCalibration:
        """The pinhole of ``f`` (no distortion) in its optical frame, named as the image's frame_id."""
        k = f.intrinsics
        return fm.CameraCalibration(
            timestamp=_stamp(t_ns), frame_id=self.frames + camera_frame_id(f.camera), width=k.width, height=k.height,
            distortion_model="plumb_bob",
            D=[0.0] * 5, K=[k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0],
            R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], P=[k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0,
                                                                1.0, 0.0])

    def image_annotations(self, s: Stains, f: CameraFrame, t_ns: int) -> fm.ImageAnnotations:
        """Each stain's outline and label projected into ``f``'s image (parts behind the camera left out)."""
        stamp = _stamp(t_ns)
        pb, Rb = _pose_matrix(s.T_board_to_world)
        points, texts = [], []
        for st in s.stains:
            colour = _colour(_GREEN if st.kappa else _RED)
            uv, ok = project(ellipse_on_board(st.centre_board_m, st.extent_board_m) @ Rb.T + pb, f)
            if ok.sum() < 3:
                continue
            points.append(fm.PointsAnnotation(timestamp=stamp, type=fm.PointsAnnotationType.LineLoop,
                                              points=[fm.Point2(x=float(u), y=float(v)) for u, v in uv[ok]],
                                              outline_color=colour, thickness=2.0))
            top = uv[ok][np.argmin(uv[ok][:, 1])]
            texts.append(fm.TextAnnotation(timestamp=stamp, position=fm.Point2(x=float(top[0]), y=float(top[1]) - 4),
                                           text=f"{st.id}: {st.remaining:.0%}" + (" kappa" if st.kappa else ""),
                                           font_size=14.0, text_color=colour,
                                           background_color=fm.Color(r=0, g=0, b=0, a=0.5)))
        return fm.ImageAnnotations(points=points, texts=texts)
