"""Joint dynamics of the iiwa 14 that the rigid-body description leaves out: rotor inertia and joint friction.

One source for the simulator (:mod:`sim.drive` applies them in PyBullet's
torque path) and for Pinocchio (:class:`~arm.robot_model.RobotModel`
puts them in ``model.armature``, ``model.damping`` and ``model.friction``),
so the controller's inertia is the simulated arm's. Per joint i the motor
torque tau_i [Nm] meets

    (M(q) + diag(Ia)) ddq + C(q, dq) dq + g(q) = tau - tau_f(dq) + J^T f
    tau_f,i = Fv_i dq_i + Fc_i tanh(dq_i / v_eps)

with Ia [kg m^2] the reflected rotor inertia (armature), Fv [Nm s/rad] the
viscous and Fc [Nm] the Coulomb friction, smoothed over v_eps [rad/s].

Where the default figures come from (LBR iiwa 14 R820):

* Fv, Fc: identified, Xu, Fan, Chen, Ng, Ang, Fang, Zhu, Zhao, "Dynamic
  Identification of the KUKA LBR iiwa Robot With Retrieval of Physical
  Parameters Using Global Optimization", IEEE Access 8, 108018-108031
  (2020), doi:10.1109/ACCESS.2020.3000997, Table 6 (the paper's optimised
  solution): Fv = 0.2968, 0.1638, 0.2853, 0.1, 0.1, 0.1, 0.1 Nm s/rad;
  Fc = 0.2377, 0.5253, 0.0334, 0.1255, 0.0734, 0.1267, 0.1372 Nm. The
  figures were read from a public transcription of that table, not from
  the paper itself; the four 0.1 entries look like a bound of the
  optimisation rather than a measurement. An independent iiwa 14 model
  agrees in size:
  AirHockeyChallenge/air_hockey_challenge, file
  air_hockey_challenge/environments/data/iiwas/iiwa_only.xml, commit
  45fcb89aa3c1344941aaced1a663f70b9f091ac4: damping 0.330, 0.212, 0.1,
  0.219, 0.186, 0.1, 0.1 Nm s/rad; frictionloss 0.384, 0.496, 0.174,
  0.375, 0.481, 0.196, 0.299 Nm.
* Ia: approximate. KUKA publishes no rotor inertias or gear ratios, and
  no identified per-joint rotor inertia of the iiwa turned up in the
  public sources searched (the papers above and Stürz, Affolter, Smith,
  IFAC-PapersOnLine 50(1), 2017; the Drake, MuJoCo Menagerie and
  robosuite iiwa models state none). The one public iiwa 14 simulation
  model found that states an armature is the AirHockeyChallenge file
  above: 0.01 kg m^2 on A7, none on A1-A6; those are the defaults. The
  iiwa's joint torque sensors sit between gear and link and its torque
  loop acts on their torque, so in torque mode the link should feel only
  part of the raw reflected inertia (rotor inertia times gear ratio
  squared). For a raw upper bound of that kind, Franka publishes
  reflected inertias for its FR3 arm (strain-wave gears, torque
  sensors): 0.606, 0.606, 0.462, 0.462, 0.206, 0.206, 0.206 kg m^2
  (RobotLocomotion/drake, manipulation/models/franka_description/README.md,
  commit 31eae0b156a77763822a5aeb4fc1633471984755); not iiwa figures.
* v_eps: a modelling choice, not a measured figure; under a torque
  |tau| < Fc a joint creeps at v_eps atanh(tau / Fc).

The ``[joints]`` config table overrides any of them (``armature_kg_m2``,
``viscous_nm_s_rad``, ``coulomb_nm``: lists of 7; ``coulomb_velocity_rad_s``),
e.g. ``LAMPS__JOINTS__ARMATURE_KG_M2="[0, 0, 0, 0, 0, 0, 0]"``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from runtime.config import check_range, check_vector, dataclass_from_table, load_config

N_JOINTS = 7

#: Xu et al. 2020, Table 6 (see the module docstring) [Nm s/rad].
VISCOUS_NM_S_RAD: tuple[float, ...] = (0.2968, 0.1638, 0.2853, 0.1000, 0.1000, 0.1000, 0.1000)
#: Xu et al. 2020, Table 6 [Nm].
COULOMB_NM: tuple[float, ...] = (0.2377, 0.5253, 0.0334, 0.1255, 0.0734, 0.1267, 0.1372)
#: AirHockeyChallenge iiwa 14 model (approximate, see the module docstring) [kg m^2].
ARMATURE_KG_M2: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.01)
#: Franka FR3 reflected inertias, a raw upper bound of comparable drives, not iiwa figures [kg m^2].
FR3_REFLECTED_INERTIA_KG_M2: tuple[float, ...] = (0.605721456, 0.605721456, 0.462474144, 0.462474144,
                                                  0.205544064, 0.205544064, 0.205544064)


@dataclass(frozen=True)
class JointDynamics:
    """Rotor inertia and friction per joint, the ``[joints]`` config table.

    armature_kg_m2 : (7,) reflected rotor inertia Ia [kg m^2], added to M's diagonal.
    viscous_nm_s_rad : (7,) viscous friction Fv [Nm s/rad].
    coulomb_nm : (7,) Coulomb friction Fc [Nm].
    coulomb_velocity_rad_s : v_eps, the speed over which Coulomb friction builds up (tanh) [rad/s].
    """

    armature_kg_m2: tuple[float, ...] = ARMATURE_KG_M2
    viscous_nm_s_rad: tuple[float, ...] = VISCOUS_NM_S_RAD
    coulomb_nm: tuple[float, ...] = COULOMB_NM
    coulomb_velocity_rad_s: float = 0.002

    def __post_init__(self) -> None:
        s = "joints"
        for name, hi in (("armature_kg_m2", 10.0), ("viscous_nm_s_rad", 50.0), ("coulomb_nm", 20.0)):
            values = check_vector(s, name, getattr(self, name), N_JOINTS)
            for v in values:
                check_range(s, name, v, 0.0, hi)
            object.__setattr__(self, name, values)
        check_range(s, "coulomb_velocity_rad_s", self.coulomb_velocity_rad_s, 1e-4, 1.0)

    @property
    def has_friction(self) -> bool:
        return any(self.viscous_nm_s_rad) or any(self.coulomb_nm)

    @property
    def is_rigid(self) -> bool:
        """No armature and no friction: the description's rigid-body dynamics alone."""
        return not any(self.armature_kg_m2) and not self.has_friction

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> JointDynamics:
        """The ``[joints]`` table (every key optional) as parameters."""
        return dataclass_from_table(cls, "joints", table)


def joint_dynamics_from_config(path: str | os.PathLike | None = None,
                               env: Mapping[str, str] | None = None) -> JointDynamics:
    """The ``[joints]`` table of the config file ``path`` (None: defaults) with ``LAMPS__JOINTS__*`` overrides."""
    return JointDynamics.from_table(load_config(path, env).table("joints"))


def friction_torque(dq: np.ndarray, jd: JointDynamics) -> tuple[np.ndarray, np.ndarray]:
    """``(tau_f, dtau_f/ddq)``, each (7,): the friction torque [Nm] that resists ``dq`` (7,) [rad/s], and its slope.

    tau_f = Fv dq + Fc tanh(dq / v_eps); the slope Fv + Fc / v_eps (1 - tanh^2) is what a
    linearly implicit step needs (the simulated drives, :mod:`sim.drive`, compile the same law).
    """
    dq = np.asarray(dq, float)
    if dq.shape != (N_JOINTS,):
        raise ValueError(f"dq must have shape ({N_JOINTS},), got {dq.shape}")
    fv, fc, v_eps = np.array(jd.viscous_nm_s_rad), np.array(jd.coulomb_nm), jd.coulomb_velocity_rad_s
    t = np.tanh(dq / v_eps)
    return fv * dq + fc * t, fv + fc / v_eps * (1.0 - t * t)
