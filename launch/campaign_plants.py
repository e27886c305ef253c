"""A campaign's plant axis (:mod:`launch.campaign`, ``--plants``): the simulated arms its cells run against.

Each plant is a ``[sim.plant]`` table (:mod:`sim.plant_params`) for the cell's simulator, given to it through the
environment (``LAMPS__SIM__PLANT__*``); the controller keeps the nominal description, so a cell meets an arm that
is not its model, as on a real robot. Seeded by the cell's seed, so a plant is the same in every campaign:

* ``nominal``: the description itself;
* ``stuerz2017``: the link masses identified on a real iiwa 14 (:data:`sim.plant_params.PROFILES`);
* ``random``: every link's mass and inertia off by up to :data:`RANDOM_MASS_ERROR` (uniform per link) and its
  centre of mass moved by up to :data:`RANDOM_COM_ERROR_M`;
* ``tool``: an unknown tool on the flange, :data:`TOOL_MASS_RANGE_KG` (uniform) at a centre of mass up to
  :data:`TOOL_COM_REACH_M` off the flange along its axis; the robot's load data stay the described eraser;
* ``arm``: both at once, ``random``'s links with ``tool``'s tool (the same draws for a seed): an arm whose links
  and tool are all off.
"""

from __future__ import annotations

import functools
import json

import numpy as np

PLANTS = ("nominal", "stuerz2017", "random", "tool", "arm")
#: The ``random`` plant's bounds: per link mass and inertia factor in [1 - e, 1 + e], centre-of-mass offset [m].
RANDOM_MASS_ERROR, RANDOM_COM_ERROR_M = 0.3, 0.02
#: The ``tool`` plant's mass range [kg] and how far along the flange axis its centre of mass may sit [m].
TOOL_MASS_RANGE_KG, TOOL_COM_REACH_M = (0.2, 1.5), 0.08


def plant_table(plant: str, seed: int) -> dict[str, object]:
    """The ``[sim.plant]`` keys of ``plant`` for seed ``seed`` (empty for ``nominal``); ValueError naming the valid
    plants for another name."""
    if plant == "nominal":
        return {}
    if plant == "stuerz2017":
        return {"profile": "stuerz2017"}
    if plant == "random":
        return {"random_mass_error": RANDOM_MASS_ERROR, "random_com_error_m": RANDOM_COM_ERROR_M, "seed": seed}
    if plant == "arm":
        return {**plant_table("random", seed), **plant_table("tool", seed)}
    if plant == "tool":
        rng = np.random.default_rng([seed, 4711])
        lo, hi = TOOL_MASS_RANGE_KG
        return {"tool_mass_kg": round(float(rng.uniform(lo, hi)), 4),
                "tool_com_m": [0.0, 0.0, round(float(rng.uniform(0.0, TOOL_COM_REACH_M)), 4)]}
    raise ValueError(f"plant {plant!r} is not one of {PLANTS}")


def plant_env(plant: str, seed: int) -> dict[str, str]:
    """The environment that gives a cell's simulator ``plant`` (:func:`plant_table`), values as JSON."""
    return {f"LAMPS__SIM__PLANT__{k.upper()}": json.dumps(v) for k, v in plant_table(plant, seed).items()}


def plant_error(plant: str, seed: int) -> float:
    """How far the plant is from the controller's model, one number for plots: the mass the model has wrong
    (each link's mass error, and an unknown tool's mass), a share of the described arm's mass."""
    from sim.plant import link_changes
    from sim.plant_params import PlantParams

    described = _described_link_mass_kg()
    params = PlantParams(**plant_table(plant, seed))  # type: ignore[arg-type]
    mass, _, _ = link_changes(params, described)
    return float((np.sum(np.abs(mass - 1.0) * described) + params.tool_mass_kg) / np.sum(described))


@functools.lru_cache(maxsize=1)
def _described_link_mass_kg() -> np.ndarray:
    """(7,) the description's link masses [kg], links A1..A7."""
    from arm.robot_model import RobotModel

    m = RobotModel().model
    return np.array([m.inertias[i].mass for i in range(1, 8)])
