"""The simulated arm that is not the description: its links, its tool, its drives and what its sensors report.

:func:`plant_urdf` writes the description changed by ``[sim.plant]`` (:class:`~sim.plant_params.PlantParams`)
as URDF text for PyBullet: each link's mass, inertia and centre of mass, and the eraser link with the extra
tool load merged in (one rigid body: mass m0 + mt, centre of mass the mass-weighted mean, inertia by the
parallel axis theorem with the load a point mass). :func:`plant_joints` gives the simulated drives' rotor
inertia and friction. :class:`Measurement` turns the simulated state into the measured one (torque bias and
noise, a delay of whole periods). :func:`tool_gravity_torque` is what a robot compensating its load adds
for a point mass on its flange. The controller's model never reads any of this.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import deque
from dataclasses import replace

import numpy as np
import pybullet as pb

from arm.description import ERASER_DEPTH_M, ERASER_LINK, URDF_PATH, urdf_attr, urdf_child
from arm.joint_dynamics import JointDynamics

from .plant_params import N_LINKS, PROFILES, PlantParams

LINK_NAMES = tuple(f"iiwa_link_{i}" for i in range(1, N_LINKS + 1))
_INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def _inertia_matrix(el: ET.Element) -> np.ndarray:
    v = {k: float(el.get(k, "0")) for k in _INERTIA_KEYS}
    return np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])


def _set_inertia(el: ET.Element, I: np.ndarray) -> None:  # noqa: E741 (I: the inertia tensor, as in the maths)
    for k, (i, j) in zip(_INERTIA_KEYS, ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        el.set(k, repr(float(I[i, j])))


def random_link_errors(p: PlantParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mass factors (7,), inertia factors (7,), centre-of-mass offsets (7, 3) [m]) drawn from ``p.seed``.

    Factors uniform in [1 - e, 1 + e] (e = ``random_mass_error``), mass and inertia independent; offsets of
    uniform length in [0, ``random_com_error_m``] along a uniformly random direction (link frame).
    """
    rng = np.random.default_rng(p.seed)
    e, c = p.random_mass_error, p.random_com_error_m
    mass = rng.uniform(1.0 - e, 1.0 + e, N_LINKS)
    inertia = rng.uniform(1.0 - e, 1.0 + e, N_LINKS)
    d = rng.normal(size=(N_LINKS, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return mass, inertia, d * rng.uniform(0.0, c, (N_LINKS, 1))


def link_changes(p: PlantParams, described_mass_kg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mass factor (7,), inertia factor (7,), centre-of-mass offset (7, 3) [m]) of links A1..A7 against the
    description whose link masses are ``described_mass_kg`` (7,): the profile (its masses; the inertia follows the
    mass), the random errors, then the explicit scales and offsets."""
    mass = np.ones(N_LINKS)
    if p.profile:
        mass = np.array(PROFILES[p.profile]) / described_mass_kg
    inertia = mass.copy()
    rm, ri, rc = random_link_errors(p)
    mass, inertia = mass * rm * np.array(p.mass_scale), inertia * ri * np.array(p.inertia_scale)
    return mass, inertia, rc + np.array(p.com_offset_m)


def plant_urdf(p: PlantParams, source: str | None = None) -> str:
    """The description (``source`` text, default the file) with ``p``'s links and tool, as URDF text."""
    root = ET.fromstring(source if source is not None else URDF_PATH.read_text())
    links = {el.get("name"): el for el in root.iter("link")}
    described = np.array([float(urdf_attr(urdf_child(links[n], "inertial/mass"), "value")) for n in LINK_NAMES])
    mass, inertia, offset = link_changes(p, described)
    for i, name in enumerate(LINK_NAMES):
        inertial = urdf_child(links[name], "inertial")
        m_el, o_el, i_el = urdf_child(inertial, "mass"), urdf_child(inertial, "origin"), urdf_child(inertial, "inertia")
        m_el.set("value", repr(float(described[i] * mass[i])))
        xyz = np.array([float(v) for v in urdf_attr(o_el, "xyz").split()]) + offset[i]
        o_el.set("xyz", " ".join(repr(float(v)) for v in xyz))
        _set_inertia(i_el, _inertia_matrix(i_el) * inertia[i])
    if p.tool_mass_kg > 0.0:
        _merge_tool(urdf_child(links[ERASER_LINK], "inertial"), p.tool_mass_kg, np.array(p.tool_com_m))
    return ET.tostring(root, encoding="unicode")


def _merge_tool(inertial: ET.Element, mt: float, ct: np.ndarray) -> None:
    """The eraser's inertial with a point mass ``mt`` [kg] at ``ct`` (3,) [m] (eraser = flange frame) merged in."""
    m_el, o_el, i_el = urdf_child(inertial, "mass"), urdf_child(inertial, "origin"), urdf_child(inertial, "inertia")
    m0, c0 = float(urdf_attr(m_el, "value")), np.array([float(v) for v in urdf_attr(o_el, "xyz").split()])
    m = m0 + mt
    c = (m0 * c0 + mt * ct) / m

    def shift(mass: float, r: np.ndarray) -> np.ndarray:  # a point mass's inertia about c (parallel axis)
        return mass * (float(r @ r) * np.eye(3) - np.outer(r, r))

    m_el.set("value", repr(m))
    o_el.set("xyz", " ".join(repr(float(v)) for v in c))
    _set_inertia(i_el, _inertia_matrix(i_el) + shift(m0, c0 - c) + shift(mt, ct - c))


def plant_joints(p: PlantParams, joints: JointDynamics) -> JointDynamics:
    """The simulated drives: ``joints`` (the [joints] table, the controller's too) with ``p``'s own values."""
    own = {k: getattr(p, k) for k in ("armature_kg_m2", "viscous_nm_s_rad", "coulomb_nm") if getattr(p, k) is not None}
    return replace(joints, **own) if own else joints


def tool_gravity_torque(client: int, robot: int, tcp_link: int, q: list[float], mass_kg: float,
                        com_flange_m: np.ndarray, zeros: list[float], g_m_s2: float) -> np.ndarray:
    """(n,) joint torques [Nm] that hold a point mass ``mass_kg`` at ``com_flange_m`` (3,) [m] (flange = eraser
    frame) against gravity at ``q``: m g J_z(point)^T. The Jacobian is taken on the pad-centre link (``tcp_link``,
    :data:`ERASER_DEPTH_M` out along the flange z, same axes), whose inertial frame is its link frame whatever
    the plant: PyBullet takes the point about a link's principal inertial frame, which a merged tool turns."""
    local = [float(com_flange_m[0]), float(com_flange_m[1]), float(com_flange_m[2]) - ERASER_DEPTH_M]
    lin, _ = pb.calculateJacobian(robot, tcp_link, local, q, zeros, zeros, physicsClientId=client)
    return mass_kg * g_m_s2 * np.array(lin[2])


class Measurement:
    """The measured state from the simulated one: torque bias and seeded noise, and a delay of whole periods.

    ``measure(q, dq, tau, wrench)`` (arrays, not kept) is called once per physics step and returns the
    measured (q, dq, tau, wrench) copies: the state of ``state_delay_periods`` steps before (the oldest held
    until that many exist), its torques plus ``torque_bias_nm`` plus N(0, ``torque_noise_nm``) noise.
    """

    def __init__(self, p: PlantParams) -> None:
        self.bias = np.array(p.torque_bias_nm)
        self.noise = np.array(p.torque_noise_nm)
        self._noisy = bool(self.noise.any())
        self.rng = np.random.default_rng([p.seed, 1])
        self.history: deque[tuple[np.ndarray, ...]] = deque(maxlen=p.state_delay_periods + 1)

    def measure(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray, wrench: np.ndarray) -> tuple[np.ndarray, ...]:
        tau_m = tau + self.bias
        if self._noisy:
            tau_m += self.rng.normal(0.0, 1.0, len(tau)) * self.noise
        self.history.append((q.copy(), dq.copy(), tau_m, wrench.copy()))
        return self.history[0]
