"""Shared test fixtures and locations."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

REPO = Path(__file__).resolve().parent.parent
#: The real demonstrations live beside the checkout, never inside it.
REAL_DEMOS = REPO.parent / "shared" / "data" / "wiping-demos" / "circular_wiping_dataset.mat"


@pytest.fixture(scope="session")
def learned_skill():
    """The skill learned from the bundled synthetic demonstration (3 stains, seed 0), what ``lamps up`` runs."""
    from lampskit.learn.learn import bundled_skill

    return bundled_skill()


@pytest.fixture(scope="session")
def learned_skill_file(learned_skill, tmp_path_factory) -> Path:
    from lampskit.core.skill import save_skill

    return save_skill(tmp_path_factory.mktemp("skill") / "skill.json", learned_skill)
