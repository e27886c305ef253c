"""The robot description shared by the simulator and the controller.

``iiwa14_eraser.urdf`` (next to this file) is the only description of the
arm: PyBullet and Pinocchio load the same file, so the sim and the
controller agree on kinematics, limits and inertia. See the file's header
for where each number comes from. The joints' rotor inertia and friction
are not in the file: :mod:`arm.joint_dynamics` gives both sides them.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

__all__ = [
    "URDF_PATH", "JOINT_NAMES", "ERASER_LINK", "TCP_FRAME", "PAD_SIZE_M", "ERASER_DEPTH_M", "urdf_child", "urdf_attr"
]

#: The KUKA LBR iiwa 14 R820 with the eraser on its flange.
URDF_PATH: Path = Path(__file__).with_name("iiwa14_eraser.urdf")

#: Actuated joints, base to flange.
JOINT_NAMES: tuple[str, ...] = tuple(f"iiwa_joint_{i}" for i in range(1, 8))
#: Link carrying the eraser's collision box (the part that touches the board).
ERASER_LINK = "eraser"
#: Frame at the centre of the felt pad surface, z out of the pad.
TCP_FRAME = "eraser_tcp"
#: Felt pad size [m]: along the tool x axis, along the tool y axis.
PAD_SIZE_M: tuple[float, float] = (0.12, 0.05)
#: The eraser's depth behind the pad face (holder 0.030 m + felt 0.005 m) [m].
ERASER_DEPTH_M: float = 0.035


def urdf_child(el: ET.Element, path: str) -> ET.Element:
    """The element at ``path`` under ``el`` of a robot description; ValueError naming what it lacks."""
    found = el.find(path)
    if found is None:
        raise ValueError(f"the robot description's <{el.tag} name={el.get('name')!r}> has no <{path}>")
    return found


def urdf_attr(el: ET.Element, name: str) -> str:
    """Attribute ``name`` of a robot description's element ``el``; ValueError naming what it lacks."""
    value = el.get(name)
    if value is None:
        raise ValueError(f"the robot description's <{el.tag}> has no {name!r}")
    return value
