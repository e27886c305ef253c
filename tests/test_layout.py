"""The package layout holds: the runtime imports only the runtime, the LAMPS core only numpy, the robot side
nothing of the simulator; no source file is over :data:`MAX_LINES` lines and no modules import each other in a
cycle (:func:`import_graph` says which imports count).

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
    own = {"lampskit", "controller", "interfaces", "runtime", "arm", "sim", "perception", "launch"}
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
    ("lampskit/core", ("lampskit.learn", "lampskit.figures", "lampskit.cli", "interfaces", "runtime", "arm",
                       "controller", "sim",
                       "perception", "launch", "scipy", "sklearn", "matplotlib")),
    ("lampskit/learn", ("lampskit.figures", "lampskit.cli", "interfaces", "runtime", "arm", "controller", "sim",
                        "perception", "launch")),
    # the learning library knows no cell: the cell hands it what it needs (launch.learn: the described arm)
    ("lampskit", ("interfaces", "runtime", "arm", "controller", "sim", "perception", "launch", "robot")),
    # the wire contract knows no process: its sessions, settings, security and the arm's model build on it (its
    # keys are Zenoh key expressions: the access list intersects them with Zenoh's own)
    ("interfaces", ("runtime", "arm", "controller", "sim", "perception", "launch", "robot", "lampskit.learn",
                    "numba", "pybullet", "pinocchio")),
    ("controller", ("lampskit.learn", "lampskit.figures", "lampskit.cli", "matplotlib", "sklearn", "sim",
                    "perception", "launch", "robot")),
    # the robot side drives the real arm: the simulated lbr stack (sim.lbr_stack) is a simulator backend, not its own
    ("robot", ("lampskit.learn", "lampskit.figures", "controller", "perception", "launch", "sim", "matplotlib",
               "sklearn")),
])
def test_no_module_imports_across_the_layout(folder, forbidden):
    """Static: a lazy import inside a function counts too."""
    hits = [f"{p.relative_to(REPO)}:{line} imports {mod}"
            for p in sorted((REPO / folder).rglob("*.py")) for line, mod in _imports(p)
            if mod == forbidden or mod.startswith(tuple(f + "." for f in forbidden)) or mod in forbidden]
    assert not hits, hits


def test_every_error_the_project_raises_on_purpose_shares_one_root():
    from arm.robot_model import IkError
    from controller.control.params import ControlConfigError
    from interfaces.errors import ConfigError, InterfaceError, MessageDecodeError
    from lampskit.errors import DemoError, LampsError, LearningError, PlanningError, SegmentationError, SkillFileError
    from launch.cli import UpError
    from perception.frames import FrameError

    for cls in (InterfaceError, MessageDecodeError, ConfigError, IkError, ControlConfigError, DemoError,
                SegmentationError, LearningError, SkillFileError, PlanningError, UpError, FrameError):
        assert issubclass(cls, LampsError), cls
    assert issubclass(ControlConfigError, ConfigError)  # a bad gain is a configuration error


# ------------------------------------------------------------------------------------------ the code's rooms
#: The longest a source file outside tests/ may be [lines]: past it, a module holds more than one purpose.
MAX_LINES = 500
#: The project's folders of source (a checkout without git: these are walked).
SOURCE_FOLDERS = ("controller", "sim", "perception", "interfaces", "runtime", "arm", "robot", "launch", "lampskit",
                  "bench", "scripts")


def _source_files() -> list[Path]:
    """Every Python file of the project outside tests/: the ones git tracks, else those of :data:`SOURCE_FOLDERS`."""
    try:
        r = subprocess.run(["git", "ls-files", "*.py"], cwd=REPO, capture_output=True, text=True, timeout=60)
        tracked = r.stdout.split() if r.returncode == 0 else []
    except OSError:
        tracked = []
    if tracked:
        files = [REPO / f for f in tracked if not f.startswith("tests/")]
    else:
        files = [p for d in SOURCE_FOLDERS for p in (REPO / d).rglob("*.py")]
    files = sorted(p for p in files if p.is_file())
    assert len(files) > 100, f"found only {len(files)} source files under {REPO}"
    return files


def test_no_source_file_is_over_the_line_limit():
    """One purpose per module: a file over the limit is split by moving a cohesive group into a module beside it."""
    over = {str(p.relative_to(REPO)): n for p in _source_files()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not over, f"over {MAX_LINES} lines: " + ", ".join(f"{f} ({n})" for f, n in sorted(over.items()))


#: ``(file, name)``: the private names one module may still import from another (none).
PRIVATE_IMPORTS_LEFT: set[tuple[str, str]] = set()


def test_no_module_imports_another_modules_private_name():
    """A name another module needs is part of its module's interface: public, documented. ``from m import _x``
    (a single leading underscore) says the two files are one purpose split in two, or ``_x`` is public."""
    hits = {(str(p.relative_to(REPO)), a.name, node.lineno) for p in _source_files()
            for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))) if isinstance(node, ast.ImportFrom)
            for a in node.names if a.name.startswith("_") and not a.name.startswith("__")}
    left = {(f, name) for f, name, _ in hits}
    assert left <= PRIVATE_IMPORTS_LEFT, sorted(f"{f}:{line} imports {name}" for f, name, line in hits
                                                if (f, name) not in PRIVATE_IMPORTS_LEFT)


def _defined_names(tree: ast.Module) -> set[str]:
    """The names a module's top level defines: assignments, functions, classes."""
    names = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    for n in tree.body:
        targets = n.targets if isinstance(n, ast.Assign) else [n.target] if isinstance(n, ast.AnnAssign) else []
        names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return names


def test_every_package_says_what_it_is_and_what_it_exports():
    """Each package's ``__init__`` has a docstring and an ``__all__``: its modules and subpackages, and the public
    names it defines itself (an ``__init__`` imports none of its modules: importing a package stays cheap)."""
    wrong = []
    for init in (p for p in _source_files() if p.name == "__init__.py"):
        tree, folder = ast.parse(init.read_text(encoding="utf-8")), init.parent
        modules = {p.stem for p in folder.glob("*.py")} | {p.name for p in folder.iterdir()
                                                           if (p / "__init__.py").is_file()}
        public = {m for m in modules | _defined_names(tree) if not m.startswith("_")}
        exported = set(next((ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
                             and any(isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)), ()))
        if not ast.get_docstring(tree) or exported != public:
            wrong.append(f"{init.relative_to(REPO)}: __all__ lacks {sorted(public - exported)}, names no such "
                         f"{sorted(exported - public)}" + ("" if ast.get_docstring(tree) else ", no docstring"))
    assert not wrong, wrong


def test_importing_every_package_is_cheap():
    loaded = _loaded_after("import arm, controller, interfaces, lampskit, launch, perception, robot, runtime, sim")
    assert not [m for m in loaded if m.split(".")[0] in ("numpy", "pybullet", "numba", "zenoh", "pinocchio")]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_only(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _import_nodes(tree: ast.AST):
    """Every import statement of a module, at any depth, except those under ``if TYPE_CHECKING:``."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(c for c in ast.iter_child_nodes(node) if not _type_checking_only(c))


def import_graph(files: list[Path]) -> dict[str, set[str]]:
    """Module -> the project's modules it imports, read from the source (ast), never by importing it.

    Imports anywhere in a module count, inside functions too (an import deferred to a call is a cycle deferred,
    not removed); only those under ``if TYPE_CHECKING:`` do not (they never run). ``import a.b`` and
    ``from a.b import c`` are edges to ``a.b.c`` when that is a module, else to ``a.b`` (not to the packages
    above it: the project's ``__init__`` files import nothing of it). Relative imports are resolved; in a folder
    without ``__init__.py`` (``bench/``, ``scripts/``: scripts run from their folder) a bare name may be a
    sibling file.
    """
    modules = {_module_name(p): p for p in files}

    def known(name: str, folder: str) -> str | None:
        if folder and f"{folder}.{name}" in modules and not (REPO / folder.replace(".", "/") / "__init__.py").exists():
            return f"{folder}.{name}"  # a script's sibling
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for me, path in modules.items():
        package = me if path.name == "__init__.py" else me.rpartition(".")[0]
        edges: set[str] = set()
        for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    up = package.split(".") if package else []
                    up = up[: len(up) - (node.level - 1)]
                    base = ".".join(up + ([node.module] if node.module else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            edges.update(t for name in targets if name and (t := known(name, package)) is not None)
        edges.discard(me)
        graph[me] = edges
    return graph


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``graph`` (Tarjan's algorithm, iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        work = [(root, iter(sorted(graph[root])))]
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                out.append(sorted(component))
    return out


def _a_cycle(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """The shortest import cycle through the component's first module: ``[a, b, ..., a]``."""
    inside, start = set(component), component[0]
    paths, seen = [[start]], {start}
    while paths:
        path = paths.pop(0)
        for w in sorted(graph[path[-1]] & inside):
            if w == start:
                return path + [start]
            if w not in seen:
                seen.add(w)
                paths.append(path + [w])
    return component


def test_the_cycle_finder_finds_cycles():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a", "e"}, "e": {"d"}, "f": set()}
    assert sorted(strongly_connected(g)) == [["a", "b", "c"], ["d", "e"], ["f"]]
    assert _a_cycle(g, ["a", "b", "c"]) == ["a", "b", "c", "a"]


def test_the_import_graph_reads_relative_lazy_and_script_imports():
    graph = import_graph(_source_files())
    assert "launch.record" in graph["launch.report_run"]  # from .record import ...
    assert "controller.control.kernels" in graph["controller.core"]  # from .control.kernels import ...
    assert "lampskit.core.planner" in graph["lampskit.cli"]  # an import inside a function
    assert "bench.bench_controller" in graph["bench.bench_robot_port"]  # a script's sibling


def test_no_modules_import_each_other_in_a_cycle():
    """A module needs the ones it imports, never the other way round: two modules that need each other are one
    purpose in two files, or share a piece that belongs in a module of its own."""
    graph = import_graph(_source_files())
    cycles = [" -> ".join(_a_cycle(graph, c)) + (f" (all of: {', '.join(c)})" if len(c) > 2 else "")
              for c in strongly_connected(graph) if len(c) > 1]
    assert not cycles, "import cycles: " + "; ".join(cycles)
