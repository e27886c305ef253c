"""docs/security.md's attack and fault table has exactly the tests marked ``attack``, as they are marked, all SAFE.

The table is written by scripts/attack_table.py from a run of those tests; this checks that nobody edited a claim
in without a test behind it, and that no marked test is missing from it (re-run the script after marking one).
"""

from __future__ import annotations

import ast
import re

from .conftest import REPO

DOC = REPO / "docs" / "security.md"


def _marked() -> dict[str, tuple[str, str, str]]:
    """``tests/<file>::<function>`` -> (case, tried, expected) of every test marked ``attack``."""
    out = {}
    for path in sorted((REPO / "tests").glob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.FunctionDef):
                continue
            for d in node.decorator_list:
                if isinstance(d, ast.Call) and isinstance(d.func, ast.Attribute) and d.func.attr == "attack":
                    out[f"tests/{path.name}::{node.name}"] = tuple(ast.literal_eval(a) for a in d.args)
    return out


def _rows() -> list[list[str]]:
    text = DOC.read_text(encoding="utf-8")
    table = text[text.index("<!-- attack-table:begin -->"):text.index("<!-- attack-table:end -->")]
    rows = [line for line in table.splitlines() if line.startswith("| ") and not line.startswith("| case |")]
    return [[c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", r)[1:-1]] for r in rows]


def test_every_row_is_a_marked_test_as_marked_and_every_marked_test_has_a_row_and_all_are_safe():
    marked = _marked()
    rows = _rows()
    assert len(marked) >= 25, sorted(marked)
    seen = set()
    for case, tried, expected, test, outcome in rows:
        function = test.strip("`").split("[")[0]
        assert function in marked, f"{test}: no test marked attack behind this row"
        assert (case, tried, expected) == marked[function], f"{test}: the row differs from its marker"
        assert outcome == "SAFE", f"{test}: {outcome}"
        seen.add(function)
    assert seen == set(marked), f"marked but not in the table (run scripts/attack_table.py): {set(marked) - seen}"


def test_the_table_is_replaced_between_its_markers_only():
    import importlib.util

    spec = importlib.util.spec_from_file_location("attack_table", REPO / "scripts" / "attack_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    table = mod.render([{"nodeid": "tests/test_x.py::test_y", "case": "2", "tried": "a | b", "expected": "c",
                         "outcome": "failed"}], "abc1234", 12.0)
    doc = mod.replace_table("head\n" + mod.BEGIN + "\nOLDROW\n" + mod.END + "\ntail\n", table)
    assert doc.startswith("head\n") and doc.endswith("\ntail\n") and "OLDROW" not in doc
    assert "| 2 | a \\| b | c | `tests/test_x.py::test_y` | UNSAFE |" in doc and "abc1234" in doc
    import pytest

    with pytest.raises(ValueError, match="needs one"):
        mod.replace_table("no markers", table)
