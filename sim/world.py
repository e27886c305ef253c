"""The PyBullet scene: the described iiwa with its eraser, and the whiteboard.

:func:`build_world` makes the same scene in any PyBullet client: the physics
client of the sim, and the renderer's mirrored client (with ``visual=True``,
the board gets a textured face the camera sees). Quaternions are converted
to PyBullet's scalar-last order here and nowhere else.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

from arm.description import ERASER_LINK, JOINT_NAMES, TCP_FRAME, URDF_PATH
from interfaces.errors import ConfigError
from interfaces.transforms import quat_wxyz_from_matrix, xyzw_from_wxyz

from .board import Board
from .params import ContactParams

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class World:
    """Body and link indices of a built scene in PyBullet client ``client``."""

    client: int
    robot: int
    board: int
    joints: tuple[int, ...]
    eraser_link: int
    tcp_link: int


def _link_index(client: int, robot: int, name: str) -> int:
    for j in range(pb.getNumJoints(robot, physicsClientId=client)):
        if pb.getJointInfo(robot, j, physicsClientId=client)[12].decode() == name:
            return j
    raise ConfigError(f"{URDF_PATH.name}: no link named {name!r}")


def _joint_indices(client: int, robot: int) -> tuple[int, ...]:
    by_name = {pb.getJointInfo(robot, j, physicsClientId=client)[1].decode(): j
               for j in range(pb.getNumJoints(robot, physicsClientId=client))}
    missing = [n for n in JOINT_NAMES if n not in by_name]
    if missing:
        raise ConfigError(f"{URDF_PATH.name}: joints {missing} missing")
    return tuple(by_name[n] for n in JOINT_NAMES)


def _board_face_mesh(board: Board) -> dict:
    """A textured quad on the board's front face (board frame at the body origin)."""
    w, h = board.size_m
    z = 1e-4  # a hair in front of the collision box, so the texture wins the depth test
    return dict(vertices=[[0, 0, z], [w, 0, z], [w, h, z], [0, h, z]], indices=[0, 1, 2, 0, 2, 3],
                uvs=[[0, 0], [1, 0], [1, 1], [0, 1]], normals=[[0, 0, 1]] * 4)


def build_world(client: int, board: Board, contact: ContactParams, q_start: np.ndarray,
                dt_s: float = 1e-3, visual: bool = False, urdf_text: str | None = None) -> World:
    """Load robot and board into ``client``; joints at ``q_start`` (7,) [rad], motors off (torque control).

    urdf_text : the arm as URDF text (the simulated plant, :func:`sim.plant.plant_urdf`); None: the description.
    The joints get no damping of PyBullet's own: rotor inertia and friction act in the torque path
    (:mod:`.drive`), with the simulated drives' figures (:func:`sim.plant.plant_joints`).
    """
    pb.resetSimulation(physicsClientId=client)
    pb.setGravity(0, 0, -GRAVITY_M_S2, physicsClientId=client)
    pb.setTimeStep(dt_s, physicsClientId=client)
    pb.setPhysicsEngineParameter(deterministicOverlappingPairs=1, numSolverIterations=50, physicsClientId=client)
    robot = _load_arm(client, urdf_text)
    joints = _joint_indices(client, robot)
    eraser, tcp = _link_index(client, robot, ERASER_LINK), _link_index(client, robot, TCP_FRAME)
    for j, q in zip(joints, q_start):
        pb.resetJointState(robot, j, float(q), 0.0, physicsClientId=client)
        pb.changeDynamics(robot, j, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0,
                          physicsClientId=client)
    # Disable the default velocity motors: joints are torque controlled.
    pb.setJointMotorControlArray(robot, joints, pb.VELOCITY_CONTROL, forces=[0.0] * len(joints),
                                 physicsClientId=client)
    pb.changeDynamics(robot, eraser, lateralFriction=contact.friction, spinningFriction=0.002,
                      rollingFriction=0.0, contactStiffness=contact.stiffness_n_m,
                      contactDamping=contact.damping_n_s_m, physicsClientId=client)
    board_body = _add_board(client, board, visual)
    return World(client, robot, board_body, joints, eraser, tcp)


def _load_arm(client: int, urdf_text: str | None) -> int:
    """The arm from the description's file, or from ``urdf_text`` through a file of its own (no meshes to find)."""
    if urdf_text is None:
        return pb.loadURDF(str(URDF_PATH), useFixedBase=True, flags=pb.URDF_USE_INERTIA_FROM_FILE,
                           physicsClientId=client)
    with tempfile.TemporaryDirectory(prefix="lamps-plant-") as tmp:
        path = Path(tmp) / URDF_PATH.name
        path.write_text(urdf_text)
        return pb.loadURDF(str(path), useFixedBase=True, flags=pb.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client)


def _add_board(client: int, board: Board, visual: bool) -> int:
    w, h = board.size_m
    t = board.thickness_m
    col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[w / 2, h / 2, t / 2],
                                  collisionFramePosition=[w / 2, h / 2, -t / 2], physicsClientId=client)
    vis = -1
    if visual:
        vis = pb.createVisualShape(pb.GEOM_MESH, rgbaColor=[1, 1, 1, 1], physicsClientId=client,
                                   **_board_face_mesh(board))
    body = pb.createMultiBody(0.0, col, vis, basePosition=board.origin_m.tolist(),
                              baseOrientation=xyzw_from_wxyz(quat_wxyz_from_matrix(board.R)),
                              physicsClientId=client)
    # Combined friction is the product of both bodies' coefficients: the eraser's value rules.
    pb.changeDynamics(body, -1, lateralFriction=1.0, physicsClientId=client)
    if visual:
        edge = pb.createVisualShape(pb.GEOM_BOX, halfExtents=[w / 2 + 0.01, h / 2 + 0.01, t / 2],
                                    visualFramePosition=[w / 2, h / 2, -t / 2 - 1e-3],
                                    rgbaColor=[0.55, 0.57, 0.6, 1], physicsClientId=client)
        pb.createMultiBody(0.0, -1, edge, basePosition=board.origin_m.tolist(),
                           baseOrientation=xyzw_from_wxyz(quat_wxyz_from_matrix(board.R)), physicsClientId=client)
    return body
