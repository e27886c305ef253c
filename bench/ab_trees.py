"""One benchmark function from two trees of the repository, alternating, in one run.

The current checkout against a baseline commit, checked out for the run in a
temporary detached ``git worktree`` (removed afterwards). Each measurement is a
fresh ``python`` process started in its tree, with that tree first on the path,
evaluating an expression in the namespace of that tree's
``bench/bench_controller.py`` (so each tree runs its own benchmark code against
its own controller); the trees take turns, so that a machine growing busier
weighs on both. A run prints the figures of both and the ratio of their
medians.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from service_procs import BenchError

#: What the child runs: the tree's bench module's namespace, the expression in argv[1], the result as JSON on a
#: line of its own (whatever the benchmark prints before it is passed through).
_CHILD = """
import json, sys
sys.path[:0] = ['.', 'bench']
import bench_controller as b
res = eval(sys.argv[1], vars(b))
print('\\nAB_RESULT ' + json.dumps(res, default=float))
"""


def resolve(repo: Path, rev: str) -> str:
    """The full commit hash of ``rev`` in ``repo``; BenchError naming it when git does not know it."""
    done = subprocess.run(["git", "rev-parse", "--verify", f"{rev}^{{commit}}"], cwd=repo, capture_output=True,
                          text=True, check=False)
    if done.returncode != 0:
        raise BenchError(f"--baseline {rev!r}: not a commit of {repo} ({done.stderr.strip()})")
    return done.stdout.strip()


@contextlib.contextmanager
def baseline_tree(repo: Path, commit: str) -> Iterator[Path]:
    """A detached worktree of ``commit`` for the run's length (with the ``../shared`` folder beside it linked,
    as the checkout has it)."""
    parent = Path(tempfile.mkdtemp(prefix="lamps-ab-"))
    tree = parent / "repo"
    shared = repo.parent / "shared"
    if shared.is_dir():
        (parent / "shared").symlink_to(shared)
    done = subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit], cwd=repo, capture_output=True,
                          text=True, check=False)
    if done.returncode != 0:
        shutil.rmtree(parent, ignore_errors=True)
        raise BenchError(f"git worktree add {commit[:12]}: {done.stderr.strip()}")
    try:
        yield tree
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=repo, capture_output=True,
                       check=False)
        shutil.rmtree(parent, ignore_errors=True)


def run_in_tree(tree: Path, expression: str, timeout_s: float) -> dict:
    """Evaluate ``expression`` in ``tree``'s ``bench_controller`` namespace in a fresh process; its result."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join((str(tree), str(tree / "bench"))))
    try:
        done = subprocess.run([sys.executable, "-c", _CHILD, expression], cwd=tree, env=env, capture_output=True,
                              text=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired as exc:
        raise BenchError(f"{expression} in {tree}: no result within {timeout_s:g} s") from exc
    for line in reversed(done.stdout.splitlines()):
        if line.startswith("AB_RESULT "):
            return json.loads(line[len("AB_RESULT "):])
    tail = (done.stderr or done.stdout).strip().splitlines()[-5:]
    raise BenchError(f"{expression} in {tree}: exit {done.returncode}, no result: " + " | ".join(tail))


def alternate(trees: dict[str, Path], expression: str, rounds: int, timeout_s: float) -> dict[str, list[dict]]:
    """``rounds`` results of ``expression`` from each tree, the trees taking turns (the order flips each round)."""
    names = list(trees)
    out: dict[str, list[dict]] = {name: [] for name in names}
    for k in range(rounds):
        for name in names if k % 2 == 0 else names[::-1]:
            print(f"ab: round {k + 1}/{rounds}, {name}: {expression}", file=sys.stderr, flush=True)
            out[name].append(run_in_tree(trees[name], expression, timeout_s))
    return out


#: The figures --baseline compares: (label, item, path into its result).
AB_FIGURES = (("tick p50 us", "tick", ("all", "p50_us")), ("tick p99 us", "tick", ("all", "p99_us")),
              ("WIPE tick p50 us", "tick", ("wipe", "p50_us")), ("WIPE tick p99 us", "tick", ("wipe", "p99_us")),
              ("closed loop in-process, ticks per wall s", "tick", ("loop_ticks_per_s",)),
              ("real-time period p50 us", "realtime", ("period_p50_us_median",)),
              ("real-time period p99 us (max of windows)", "realtime", ("period_p99_us_max",)),
              ("real-time states unanswered per 10,000", "realtime", ("overruns_per_10k",)))


def compare_with(repo: Path, rev: str, rounds: int, quick: bool) -> int:
    """bench_controller's items 1 and 2 from ``repo``'s checkout and from ``rev``, alternating ``rounds`` times;
    prints the table (exit status: 1 when a run failed, named on stderr)."""

    def dig(r: dict, path: tuple[str, ...]) -> float:
        for k in path:
            r = r[k]
        return float(r)  # type: ignore[arg-type]

    here = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=repo, capture_output=True, text=True,
                          check=False).stdout.strip() or "this checkout"
    duration = 10.0 if quick else 60.0
    items = {"tick": "bench_tick(bundled_skill())", "realtime": f"bench_realtime({duration})"}
    try:
        commit = resolve(repo, rev)
        with baseline_tree(repo, commit) as base:
            trees = {here: repo, commit[:7]: base}
            res = {item: alternate(trees, expr, rounds, 900.0) for item, expr in items.items()}
    except BenchError as exc:
        print(f"bench_controller: {exc}", file=sys.stderr)
        return 1
    print(f"\n| {rounds} rounds each, alternating, one run | {here} | {commit[:7]} | ratio |\n|---|---|---|---|")
    for label, item, path in AB_FIGURES:
        a, b = (float(np.median([dig(r, path) for r in res[item][name]])) for name in trees)
        print(f"| {label} | {a:.1f} | {b:.1f} | {a / b:.2f} |" if b else f"| {label} | {a:.1f} | {b:.1f} | - |")
    print(f"\ncpu count {os.cpu_count()}, Python {platform.python_version()}, {platform.machine()}")
    print(f"reproduce: .venv/bin/python bench/bench_controller.py --baseline {commit[:7]} --rounds {rounds}"
          + (" --quick" if quick else ""))
    return 0
