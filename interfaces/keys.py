"""Key expressions of the LAMPS cell (see ../shared/DESIGN.md, "Keys").

Every key lives under one prefix, ``lamps/<robot-id>`` by default, so two
cells can share a Zenoh network without hearing each other.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .errors import ConfigError

DEFAULT_ROBOT_ID = "iiwa"
_CHUNK = re.compile(r"^[A-Za-z0-9_\-.]+$")


def _check_chunks(text: str, what: str) -> str:
    chunks = text.split("/")
    if not text or not all(_CHUNK.match(c) for c in chunks):
        raise ConfigError(
            f"{what} {text!r} must be '/'-separated chunks of letters, digits, '_', '-' or '.' "
            "(no wildcards, no empty chunks)"
        )
    return text


@dataclass(frozen=True)
class Keys:
    """All key expressions under ``prefix`` (e.g. ``lamps/iiwa``)."""

    prefix: str = f"lamps/{DEFAULT_ROBOT_ID}"

    def __post_init__(self) -> None:
        _check_chunks(self.prefix, "key prefix")

    @classmethod
    def for_robot(cls, robot_id: str = DEFAULT_ROBOT_ID) -> Keys:
        """Keys under the default prefix ``lamps/<robot_id>``."""
        return cls(f"lamps/{_check_chunks(robot_id, 'robot id')}")

    def _k(self, suffix: str) -> str:
        return f"{self.prefix}/{suffix}"

    @property
    def robot_state(self) -> str:
        """sim/adapter -> controller, 1 kHz: :class:`~interfaces.messages.RobotState`."""
        return self._k("robot/state")

    @property
    def robot_command(self) -> str:
        """controller -> sim/adapter, 1 kHz: :class:`~interfaces.messages.TorqueCommand`."""
        return self._k("robot/command")

    def camera_frame(self, camera: str) -> str:
        """sim/camera -> perception, 10-30 Hz: :class:`~interfaces.messages.CameraFrame`."""
        return self._k(f"camera/{_check_chunks(camera, 'camera name')}/frame")

    @property
    def camera_frames(self) -> str:
        """Wildcard over every camera's frames."""
        return self._k("camera/*/frame")

    @property
    def perception_stains(self) -> str:
        """perception -> controller, >= 10 Hz: :class:`~interfaces.messages.Stains`."""
        return self._k("perception/stains")

    @property
    def perception_status(self) -> str:
        """perception -> anyone: :class:`~interfaces.messages.ServiceStatus`."""
        return self._k("perception/status")

    @property
    def perception_debug(self) -> str:
        """perception -> anyone, off by default: :class:`~interfaces.messages.CameraFrame`."""
        return self._k("perception/debug")

    @property
    def controller_status(self) -> str:
        """controller -> anyone, 20-50 Hz: :class:`~interfaces.messages.ControllerStatus`."""
        return self._k("controller/status")

    @property
    def controller_trace(self) -> str:
        """controller -> recorders, with each status: :class:`~interfaces.messages.ControllerTrace` (every tick)."""
        return self._k("controller/trace")

    @property
    def controller_estop(self) -> str:
        """anyone authenticated -> controller and robot side, event: :class:`~interfaces.messages.Estop` engaging the
        e-stop (a release here is ignored: releases have their own key, which access control gives the operator)."""
        return self._k("controller/estop")

    @property
    def controller_estop_release(self) -> str:
        """operator -> controller and robot side, event: :class:`~interfaces.messages.Estop` with ``engaged=False``."""
        return self._k("controller/estop/release")

    @property
    def sim_truth(self) -> str:
        """sim -> tests, reports, ~10 Hz: :class:`~interfaces.messages.SimTruth`."""
        return self._k("sim/truth")

    @property
    def sim_status(self) -> str:
        """sim -> anyone: :class:`~interfaces.messages.ServiceStatus`."""
        return self._k("sim/status")

    @property
    def robot_status(self) -> str:
        """real-robot adapter -> anyone: :class:`~interfaces.messages.ServiceStatus` (armed, guards, timing)."""
        return self._k("robot/status")

    @property
    def robot_introduction(self) -> str:
        """robot side -> controller, every 0.5 s: :class:`~interfaces.messages.Introduction` (its certificate and the
        nonce of this start: :mod:`interfaces.arm_auth`)."""
        return self._k("robot/introduction")

    @property
    def controller_introduction(self) -> str:
        """controller -> robot side, every 0.5 s: :class:`~interfaces.messages.Introduction` (its certificate and
        session: :mod:`interfaces.arm_auth`)."""
        return self._k("controller/introduction")

    @property
    def robot_arm(self) -> str:
        """operator -> real-robot adapter, event: :class:`~interfaces.messages.ArmRequest`."""
        return self._k("robot/arm")

    def alive(self, service: str) -> str:
        """Liveliness token of ``service`` (presence only)."""
        return self._k(f"alive/{_check_chunks(service, 'service name')}")

    @property
    def alive_any(self) -> str:
        return self._k("alive/*")
