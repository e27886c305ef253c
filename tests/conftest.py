"""Shared test fixtures and locations."""

from __future__ import annotations

import json
import os
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")
# Services started by the tests without an identity run plain TCP on loopback on purpose (a service refuses to
# start so unless told: runtime/service_security.py); tests of security give identities, and the test of the
# refusal removes this. `lamps up` never passes it on to its services.
os.environ.setdefault("LAMPS_ZENOH_INSECURE", "true")
# pytest's workers (gw0, gw1, ...) draw their listening ports from disjoint slices of runtime/ports.py's range, so
# two workers never pick the same port between choosing and binding it; the services they start inherit the slice.
_worker = os.environ.get("PYTEST_XDIST_WORKER", "")
if _worker.startswith("gw") and _worker[2:].isdigit() and "LAMPS_PORT_RANGE" not in os.environ:
    _slice = 625  # 8 workers across runtime/ports.py's DEFAULT_RANGE, 27000-32000
    _lo = 27000 + (int(_worker[2:]) % 8) * _slice
    os.environ["LAMPS_PORT_RANGE"] = f"{_lo}-{_lo + _slice}"

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


# -------------------------------------------------------------------------------- attacks and faults tried
#: ``LAMPS_ATTACK_RESULTS=FILE``: each test marked ``@pytest.mark.attack(case, tried, expected)`` adds its outcome
#: (scripts/attack_table.py runs them and writes docs/security.md's table from the file).
_ATTACK_RESULTS: list[dict] = []


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    mark = item.get_closest_marker("attack")
    if mark is None or not os.environ.get("LAMPS_ATTACK_RESULTS"):
        return
    if rep.when == "call" or (rep.when == "setup" and not rep.passed):
        case, tried, expected = (str(x) for x in mark.args)
        _ATTACK_RESULTS.append({"nodeid": item.nodeid, "case": case, "tried": tried, "expected": expected,
                                "outcome": rep.outcome, "seconds": round(rep.duration, 1)})


def pytest_sessionfinish(session, exitstatus):
    path = os.environ.get("LAMPS_ATTACK_RESULTS")
    if path and _ATTACK_RESULTS:
        from lampskit.atomic import write_text_atomic

        write_text_atomic(Path(path), json.dumps(_ATTACK_RESULTS, indent=1) + "\n")
