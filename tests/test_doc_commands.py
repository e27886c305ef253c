"""Every ``lamps`` command line in README.md and docs/*.md names a real subcommand and real options.

Each fenced ``sh`` / ``bash`` / ``console`` block is read line by line (continuations joined, comments and leading
``VAR=value`` assignments dropped); a line that runs ``lamps``, ``./lamps`` or ``.venv/bin/lamps`` has its
subcommand's ``--help`` run in-process, and every ``--option`` the line uses must appear in that help. A renamed
subcommand or flag fails here, not in a user's terminal.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex

import pytest

from runtime.cli import COMMANDS, main

from .conftest import REPO

DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
_FENCE = re.compile(r"^```(sh|bash|console|shell)\s*\n(.*?)^```", re.M | re.S)
_LAMPS = ("lamps", "./lamps", ".venv/bin/lamps")


def _command_lines() -> list[tuple[str, list[str]]]:
    """(where, argv after the program) of every lamps invocation in a shell block of the docs."""
    out = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for m in _FENCE.finditer(text):
            line_no = text[:m.start()].count("\n") + 1
            for raw in m.group(2).replace("\\\n", " ").splitlines():
                line = raw.strip().removeprefix("$ ")
                for part in re.split(r"&&|\|\||;|\|", line.split(" #")[0] if not line.startswith("#") else ""):
                    try:
                        words = shlex.split(part)
                    except ValueError:
                        continue
                    while words and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[0]):
                        words = words[1:]
                    if words and words[0] in _LAMPS:
                        out.append((f"{doc.name}:{line_no}", words[1:]))
    return out


LINES = _command_lines()


def _help(sub: str) -> str:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        try:
            main([sub, "--help"])
        except SystemExit:
            pass
    return buf.getvalue()


def test_the_docs_have_lamps_command_lines():
    assert len(LINES) >= 10, LINES
    assert any(argv[:1] == ["up"] for _, argv in LINES)


@pytest.mark.parametrize("sub", sorted({argv[0] for _, argv in LINES if argv and not argv[0].startswith("-")}))
def test_every_documented_subcommand_exists_and_takes_the_documented_options(sub):
    assert sub in COMMANDS, f"{sub!r} is no lamps command: {[w for w, a in LINES if a[:1] == [sub]]}"
    text = _help(sub)
    assert text.strip(), f"lamps {sub} --help printed nothing"
    for where, argv in LINES:
        if argv[:1] != [sub]:
            continue
        for word in argv[1:]:
            if word.startswith("--"):
                flag = word.split("=")[0]
                assert re.search(rf"(?<![\w-]){re.escape(flag)}(?![\w-])", text), \
                    f"{where}: lamps {sub} has no option {flag}"


def test_top_level_options_in_the_docs_exist():
    for where, argv in LINES:
        if argv and argv[0].startswith("-"):
            assert argv[0] in ("--version", "-V", "--help", "-h"), f"{where}: lamps {argv[0]}"
