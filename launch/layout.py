"""The Foxglove layout of a cell: 3D scene, camera with stains, force and tracking plots, phase, joints.

:func:`cell_layout` builds it for a key prefix (robot id) and camera in the
classic layout format the Foxglove app and Lichtblick import ("Import
layout"): ``configById`` (one config per panel id ``<Type>!<name>``),
``layout`` (the mosaic tree of panel ids), ``globalVariables``,
``userNodes``, ``playbackConfig``. ``config/foxglove/lamps.json`` is it for
the default cell (``lamps foxglove --write-layout FILE [--robot-id ID]``
writes another; :func:`site_layout` a tab per cell of a site).
:func:`layout_paths` lists every topic and message path it reads, so the
tests check each against a real recording.

Topics (see :mod:`launch.scene` and :mod:`launch.record`): the 3D panel
shows ``scene/tf``, ``scene/robot`` (the arm), ``scene/board`` (board and
stains) in the ``world`` frame; the image panel the camera's JPEG frames
with its calibration and the stains' outlines; the plots the controller
trace rows (``controller/trace/plot``: reference vs measured pad in the
board frame, force and press command) and the robot's joint states; the
state-transitions panel the controller's phase.
"""

from __future__ import annotations

import re
from typing import Any

from interfaces.keys import Keys

#: (panel id, title) of every panel, in reading order.
PANELS = ("3D!scene", "Image!camera", "Plot!force", "Plot!tracking", "StateTransitions!phase", "Plot!joints",
          "Plot!torques")


def _series(path: str, label: str, color: str | None = None) -> dict:
    s = {"value": path, "enabled": True, "timestampMethod": "receiveTime", "label": label}
    if color:
        s["color"] = color
    return s


def cell_layout(keys: Keys | None = None, camera: str = "board") -> dict[str, Any]:
    """The layout (a JSON-able dict) for the cell under ``keys`` (default: the default cell) and ``camera``."""
    keys = keys or Keys()
    p = keys.prefix
    frame = keys.camera_frame(camera)
    trace = f"{keys.controller_trace}/plot"
    status, state = keys.controller_status, keys.robot_state
    config = {
        "3D!scene": {
            "followTf": "world", "followMode": "follow-pose",
            "cameraState": {"distance": 2.0, "perspective": True, "phi": 60, "thetaOffset": 90,
                            "target": [0.55, 0, 0.6], "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1],
                            "fovy": 45, "near": 0.01, "far": 100},
            "scene": {"transforms": {"showLabel": False, "axisScale": 0.5}},
            "transforms": {"frame:world": {"visible": True}},
            "topics": {f"{p}/scene/tf": {"visible": True}, f"{p}/scene/robot": {"visible": True},
                       f"{p}/scene/board": {"visible": True}, frame: {"visible": False}},
            "layers": {"grid": {"visible": True, "frameLocked": True, "label": "Grid", "instanceId": "grid",
                                "layerId": "foxglove.Grid", "size": 2, "divisions": 20, "lineWidth": 1,
                                "color": "#248eff80", "position": [0, 0, 0], "rotation": [0, 0, 0],
                                "order": 1}},
        },
        "Image!camera": {
            "imageMode": {"imageTopic": frame, "calibrationTopic": f"{frame}/calibration",
                          "annotations": {f"{frame}/annotations": {"visible": True}}},
            "topics": {}, "layers": {}, "transforms": {}, "scene": {},
        },
        "Plot!force": {
            "title": "Contact force [N]",
            "paths": [_series(f"{trace}.force_n", "measured", "#e8552f"),
                      _series(f"{trace}.press_n", "press command", "#4e98e2"),
                      _series(f"{status}.normal_force_n", "status (10 Hz)", "#a0a0a0")],
            "showLegend": True, "legendDisplay": "left", "sidebarDimension": 150, "isSynced": True,
            "xAxisVal": "timestamp",
        },
        "Plot!tracking": {
            "title": "Pad in the board frame: reference vs measured [m]",
            "paths": [_series(f"{trace}.ref_x", "x reference", "#4e98e2"), _series(f"{trace}.x", "x", "#1f5f9f"),
                      _series(f"{trace}.ref_y", "y reference", "#f5a742"), _series(f"{trace}.y", "y", "#b06d10"),
                      _series(f"{trace}.h", "height above the board", "#6cbd5a")],
            "showLegend": True, "legendDisplay": "left", "sidebarDimension": 150, "isSynced": True,
            "xAxisVal": "timestamp",
        },
        "StateTransitions!phase": {
            "paths": [{"value": f"{status}.phase", "timestampMethod": "receiveTime", "label": "phase"},
                      {"value": f"{status}.current_mp", "timestampMethod": "receiveTime", "label": "MP"}],
            "isSynced": True,
        },
        "Plot!joints": {
            "title": "Joints: position [rad], velocity [rad/s]",
            "paths": [*(_series(f"{state}.q_rad[{i}]", f"q{i + 1}") for i in range(7)),
                      *(_series(f"{state}.dq_rad_s[{i}]", f"dq{i + 1}") for i in range(7))],
            "showLegend": True, "legendDisplay": "left", "sidebarDimension": 150, "isSynced": True,
            "xAxisVal": "timestamp",
        },
        "Plot!torques": {
            "title": "Joint torques: commanded vs measured [Nm]",
            "paths": [*(_series(f"{keys.robot_command}.tau_nm[{i}]", f"command {i + 1}") for i in range(7)),
                      *(_series(f"{state}.tau_nm[{i}]", f"measured {i + 1}") for i in range(7))],
            "showLegend": True, "legendDisplay": "left", "sidebarDimension": 150, "isSynced": True,
            "xAxisVal": "timestamp",
        },
    }
    mosaic = {
        "direction": "row", "splitPercentage": 55,
        "first": {"direction": "column", "splitPercentage": 60, "first": "3D!scene", "second": "Image!camera"},
        "second": {"direction": "column", "splitPercentage": 30, "first": "Plot!force",
                   "second": {"direction": "column", "splitPercentage": 40, "first": "Plot!tracking",
                              "second": {"direction": "column", "splitPercentage": 30,
                                         "first": "StateTransitions!phase",
                                         "second": {"direction": "row", "splitPercentage": 50,
                                                    "first": "Plot!joints", "second": "Plot!torques"}}}},
    }
    return {"configById": config, "layout": mosaic, "globalVariables": {}, "userNodes": {},
            "playbackConfig": {"speed": 1.0}}


def site_layout(cells: list[Keys], camera: str = "board") -> dict[str, Any]:
    """The layout of a site's cells (``lamps foxglove --cells``): a Tab panel, one tab per cell, each tab the cell's
    :func:`cell_layout` (panel ids ``<Type>!<name>-<robot id>``), its 3D panel following the cell's own frame tree
    (``<robot id>/world``, :func:`launch.scene.cell_frames`)."""
    from .scene import WORLD, cell_frames

    if not cells:
        raise ValueError("a site's layout needs at least one cell")
    config: dict[str, Any] = {}
    tabs = []
    for keys in cells:
        robot = cell_frames(keys)[:-1]
        one = cell_layout(keys, camera)
        ids = {pid: f"{pid}-{robot}" for pid in one["configById"]}
        for pid, cfg in one["configById"].items():
            if "followTf" in cfg:
                cfg = {**cfg, "followTf": f"{robot}/{WORLD}",
                       "transforms": {f"frame:{robot}/{WORLD}": {"visible": True}}}
            config[ids[pid]] = cfg

        def renamed(node):
            if isinstance(node, str):
                return ids[node]  # noqa: B023 (called within this iteration)
            return {k: renamed(v) if k in ("first", "second") else v for k, v in node.items()}
        tabs.append({"title": robot, "layout": renamed(one["layout"])})
    config["Tab!cells"] = {"activeTabIdx": 0, "tabs": tabs}
    return {"configById": config, "layout": "Tab!cells", "globalVariables": {}, "userNodes": {},
            "playbackConfig": {"speed": 1.0}}


_PATH = re.compile(r"^(?P<topic>[^.\[]+)\.(?P<field>[A-Za-z_][A-Za-z0-9_]*)(?:\[(?P<index>\d+)\])?$")


def layout_paths(layout: dict) -> tuple[set[str], list[tuple[str, str, int | None]]]:
    """(every topic the layout shows, every message path as (topic, field, index or None)) it reads."""
    topics: set[str] = set()
    paths = []
    for cfg in layout["configById"].values():
        topics.update(t for t, s in cfg.get("topics", {}).items() if s.get("visible", True))
        mode = cfg.get("imageMode") or {}
        topics.update(t for t in (mode.get("imageTopic"), mode.get("calibrationTopic")) if t)
        topics.update(mode.get("annotations", {}))
        for s in cfg.get("paths", []):
            m = _PATH.match(s["value"])
            if m is None:
                raise ValueError(f"layout: cannot read the message path {s['value']!r}")
            paths.append((m.group("topic"), m.group("field"), int(m.group("index")) if m.group("index") else None))
            topics.add(m.group("topic"))
    return topics, paths
