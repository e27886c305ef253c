"""No history in the docs, the code's comments or its tests: what changed lives in git and CHANGELOG.md.

README.md, docs/*.md and every tracked source file are searched for phrases that narrate the past ("the
review", "an earlier run", "used to be", ...). Comparisons that matter are same-run A/B measurements, stated as
such.
"""

from __future__ import annotations

import re
import subprocess

from .conftest import REPO

PHRASES = re.compile(r"the review|this session|last session|earlier run|an earlier run|predates?\b|used to be|"
                     r"\bpreviously\b|rounds? of work|before the fix|was changed to|no longer (?:does|is|has|needs)",
                     re.I)
#: This file names the phrases; CHANGELOG.md is where history belongs.
EXEMPT = {"tests/test_docs_history.py", "CHANGELOG.md"}


def _tracked() -> list[str]:
    out = subprocess.run(["git", "ls-files", "*.md", "*.py", "*.toml", "*.yml", "*.sh", "Dockerfile"], cwd=REPO,
                         capture_output=True, text=True)
    return [p for p in out.stdout.split() if p not in EXEMPT]


def test_no_history_wording_in_docs_code_or_tests():
    files = _tracked()
    assert "README.md" in files and any(f.startswith("docs/") for f in files)
    hits = []
    for name in files:
        for i, line in enumerate((REPO / name).read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if PHRASES.search(line):
                hits.append(f"{name}:{i}: {line.strip()[:120]}")
    assert not hits, "history wording (state what is true now; history goes to CHANGELOG.md):\n" + "\n".join(hits)


def test_the_changelog_and_the_version_agree():
    import tomllib

    version = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
    text = (REPO / "CHANGELOG.md").read_text()
    assert "## [Unreleased]" in text and f"## [{version}]" in text, version
