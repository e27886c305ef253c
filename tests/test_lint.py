"""Lint and types: the tree passes ``ruff check`` with pyproject.toml's settings, and mypy checks every package.

``./run-tests`` runs ``ruff check .`` and ``mypy`` before the suite (docs/architecture.md#lint-and-types); this test
keeps ruff's verdict in the suite too, so a finding also fails a ``./run-tests tests/...`` run. Both tools come
with the ``test`` extra of pyproject.toml.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def test_the_tree_passes_ruff():
    """``ruff check .`` from the repository root: pyflakes, pycodestyle, bugbear, isort and pyupgrade, tests too."""
    if importlib.util.find_spec("ruff") is None:
        pytest.skip("ruff is not installed in this Python (pip install -e '.[test]' brings it; CI has it)")
    r = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, f"ruff check . found problems (ruff check --fix . repairs the mechanical ones):\n" \
                              f"{r.stdout}{r.stderr}"


def test_the_rule_sets_a_careful_team_keeps_are_selected():
    """pyflakes (F), pycodestyle errors and warnings (E, W), bugbear (B), isort (I) and pyupgrade (UP) at 120
    columns for Python 3.11; every rule ignored says why on its line."""
    ruff = _pyproject()["tool"]["ruff"]
    assert ruff["line-length"] == 120 and ruff["target-version"] == "py311"
    assert set(ruff["lint"]["select"]) >= {"F", "E", "W", "B", "I", "UP"}
    text = (REPO / "pyproject.toml").read_text(encoding="utf-8")
    block = text[text.index("[tool.ruff.lint]"):text.index("[tool.ruff.lint.per-file-ignores]")]
    ignored = [line for line in block.splitlines() if line.strip().startswith('"')]
    assert all("#" in line for line in ignored), f"an ignored rule without its reason: {ignored}"


def test_mypy_checks_every_package_the_project_installs():
    """The packages of ``[tool.mypy]`` are those setuptools installs (a new package is type-checked too)."""
    project = _pyproject()
    installed = {p.rstrip("*") for p in project["tool"]["setuptools"]["packages"]["find"]["include"]}
    assert set(project["tool"]["mypy"]["packages"]) == installed
    assert project["tool"]["mypy"]["python_version"] == "3.11"
