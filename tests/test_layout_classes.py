"""The classes on the 1 kHz path stay small enough to read: at most :data:`MAX_ATTRIBUTES` instance attributes.

A class that grows past it is split by purpose into collaborators it owns (the lbr adapter's inbox, readings,
sender and watches; the robot server's e-stop, served controller and cycle record; the controller service's
link, answers and status), each with its own docstring, not into bags of fields.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

MAX_ATTRIBUTES = 20
#: The packages whose code runs on (or beside) the loops' 1 kHz path.
ON_THE_PATH = ("controller", "robot", "sim", "lampskit/core", "runtime")
#: Classes of those packages off the 1 kHz path, with why (the camera renders at its frame rate, on its own thread
#: or process).
OFF_THE_PATH = {"sim/analytic_camera.py:AnalyticCamera": "the sim's camera, at the frame rate"}


def instance_attributes(cls: ast.ClassDef) -> set[str]:
    """The names assigned as ``self.<name>`` anywhere in the class's body."""
    return {n.attr for n in ast.walk(cls) if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
            and n.value.id == "self" and isinstance(n.ctx, ast.Store)}


def test_instance_attributes_counts_assignments_to_self_only():
    tree = ast.parse("class A:\n def __init__(self):\n  self.a = 1\n  self.b.c = 2\n  x.d = 3\n  self.a += 1\n")
    cls = tree.body[0]
    assert isinstance(cls, ast.ClassDef)
    assert instance_attributes(cls) == {"a"}  # self.b.c stores into b's object, not into self


def test_no_class_on_the_1khz_path_holds_more_than_twenty_attributes():
    over = {}
    for folder in ON_THE_PATH:
        for path in sorted((REPO / folder).rglob("*.py")):
            for cls in (n for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.ClassDef)):
                name = f"{path.relative_to(REPO)}:{cls.name}"
                k = len(instance_attributes(cls))
                if k > MAX_ATTRIBUTES and name not in OFF_THE_PATH:
                    over[name] = k
    assert not over, f"classes over {MAX_ATTRIBUTES} attributes (split them by purpose): {over}"
