"""The package layout holds: the runtime imports only the runtime, the LAMPS core only numpy.

Checked in a fresh interpreter (what a process really loads) and statically
(an import inside a function would escape the first check until it runs).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

#: What the 1 kHz controller process must never load: the learner, figures, file readers, heavy optimisers.
NOT_IN_THE_CONTROLLER = ("lampskit.learn", "lampskit.figures", "lampskit.cli", "matplotlib", "sklearn",
                         "scipy.optimize", "scipy.io", "scipy.signal", "cv2", "pybullet")


def _loaded_after(code: str) -> list[str]:
    """sys.modules of a fresh interpreter after running ``code``."""
    probe = f"import sys, json\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    r = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def _third_party(modules: list[str]) -> set[str]:
    own = {"lampskit", "controller", "interfaces", "sim", "perception", "launch"}
    tops = {m.split(".")[0] for m in modules}
    return {m for m in tops if m not in sys.stdlib_module_names and m not in own and not m.startswith("_")
            and m not in ("cmeel_pth",) and "editable" not in m}


def test_the_controller_service_loads_no_learning_plotting_or_reader_module():
    loaded = _loaded_after("import controller.service, controller.cli")
    bad = [m for m in loaded if m.startswith(NOT_IN_THE_CONTROLLER)]
    assert not bad, bad
    assert "lampskit.core.periodic_runner" in loaded  # it does run the LAMPS core


def test_the_lamps_core_imports_only_numpy():
    core = sorted(p.stem for p in (REPO / "lampskit" / "core").glob("*.py") if p.stem != "__init__")
    assert {"periodic", "periodic_runner", "transitional", "transitional_runner", "skill", "planner"} <= set(core)
    loaded = _loaded_after("\n".join(f"import lampskit.core.{m}" for m in core))
    assert _third_party(loaded) == {"numpy"}, _third_party(loaded)
    ours = {m for m in loaded if m.split(".")[0] == "lampskit"}
    assert all(m.startswith(("lampskit.core", "lampskit.errors", "lampskit.atomic")) or m == "lampskit"
               for m in ours), ours


def _imports(path: Path) -> list[tuple[int, str]]:
    """Every module a file imports, anywhere in it (functions included), with its line."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module))
    return out


@pytest.mark.parametrize("folder, forbidden", [
    ("lampskit/core", ("lampskit.learn", "lampskit.figures", "lampskit.cli", "interfaces", "controller", "sim",
                       "perception", "launch", "scipy", "sklearn", "matplotlib")),
    ("lampskit/learn", ("lampskit.figures", "lampskit.cli", "interfaces", "controller", "sim", "perception", "launch")),
    ("controller", ("lampskit.learn", "lampskit.figures", "lampskit.cli", "matplotlib", "sklearn", "sim",
                    "perception", "launch", "robot")),
    ("robot", ("lampskit.learn", "lampskit.figures", "controller", "perception", "launch", "matplotlib", "sklearn")),
])
def test_no_module_imports_across_the_layout(folder, forbidden):
    """Static: a lazy import inside a function counts too."""
    hits = [f"{p.relative_to(REPO)}:{line} imports {mod}"
            for p in sorted((REPO / folder).rglob("*.py")) for line, mod in _imports(p)
            if mod == forbidden or mod.startswith(tuple(f + "." for f in forbidden)) or mod in forbidden]
    assert not hits, hits


def test_every_error_the_project_raises_on_purpose_shares_one_root():
    from controller.control.params import ControlConfigError
    from interfaces.errors import ConfigError, InterfaceError, MessageDecodeError
    from interfaces.robot_model import IkError
    from lampskit.errors import (DemoError, LampsError, LearningError, PlanningError, SegmentationError,
                                 SkillFileError)
    from launch.cli import UpError
    from perception.frames import FrameError

    for cls in (InterfaceError, MessageDecodeError, ConfigError, IkError, ControlConfigError, DemoError,
                SegmentationError, LearningError, SkillFileError, PlanningError, UpError, FrameError):
        assert issubclass(cls, LampsError), cls
    assert issubclass(ControlConfigError, ConfigError)  # a bad gain is a configuration error
