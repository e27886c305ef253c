"""A whole network-free cell on the identified plant: the ``[sim.plant]`` table reaches the sim through the
cell's environment, the controller keeps the description, and the board is cleaned."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from runtime.config import load_config
from sim.params import SimParams

from .conftest import REPO

PLANT_ENV = {"LAMPS__SIM__PLANT__PROFILE": '"stuerz2017"', "LAMPS__SIM__PLANT__TOOL_MASS_KG": "0.3"}


def test_the_plant_comes_from_the_environment_as_the_cell_gives_it():
    plant = SimParams.from_table(load_config(None, PLANT_ENV).table("sim")).plant
    assert plant.profile == "stuerz2017" and plant.tool_mass_kg == 0.3


@pytest.mark.slow
def test_a_network_free_cell_on_the_identified_plant_cleans_its_board(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("LAMPS__SIM__PLANT__")}
    env.update(PLANT_ENV)
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "runtime.cli", "up", "--no-network", "--seed", "0", "--out",
                        str(out), "-q", "--max-duration", "600"], cwd=REPO, env=env, capture_output=True, text=True,
                       timeout=900)
    assert (out / "report.json").exists(), r.stderr[-3000:]
    report = json.loads((out / "report.json").read_text())
    assert report["outcome"] == "cleaned", report["outcome"]
    assert report["dirt_removed_fraction"] >= 0.95
    assert report["max_normal_force_n"] < 40.0
