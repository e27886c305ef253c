"""The controller on simulated arms that are not its model, with and without what it learns of the arm.

Usage: .venv/bin/python bench/bench_plant.py [--seed 0] [--modes off,on] [--plants main|extra|all]
       [--controllers plain,learning] [--json OUT]

Each plant is one network-free lock-step cell (``lamps up --no-network``, :mod:`launch.local_cell`: the
compose file's sim, controller, perception and recorder in one process), the default wall board with the
seed's three stains, the bundled demo learned once (the first cell) and its skill given to every cell.
The plant is set through the environment (``LAMPS__SIM__PLANT__*``, the ``[sim.plant]`` table, read by
the sim only); the controller loads the description as always. Plants:

* ``nominal``: the description (today's cell);
* ``+15 % links, +0.5 kg tool``: every link's mass and inertia x1.15, 0.5 kg more on the flange at the
  eraser's centre of mass (0, 0, 0.0175) m;
* ``+30 % links, +1.0 kg tool``: x1.30 and 1.0 kg;
* ``stuerz2017``: the identified link masses (:data:`sim.plant_params.STUERZ_2017_LINK_MASS_KG`).

``--plants extra`` (or ``all``): the measured state 3 periods late on the nominal arm, and one seeded plant of
the campaign bounds (link masses and inertias within +-30 %, centres of mass within 2 cm, 1.5 kg more
on the flange; plant seed 1).

Each in both robot modes unless ``--modes`` says otherwise: ``off`` (``gravity_compensated = false``, the
default cell: the controller compensates gravity with its nominal model) and ``on`` (the simulated robot
compensates its own true weight and the tool by its load data, left at the described eraser, so an added
tool is not compensated). Per cell, from its ``report.json``: outcome, dirt removed, normal force while
wiping mean +- std, its maximum, tracking RMS in contact (in-plane reference vs measured pad while wiping),
and the flange load the controller estimated before its first wipe (``arm_model`` of the report).

Each cell with both controllers unless ``--controllers`` says otherwise (same seeds, same run): ``plain``, the
controller with ``[controller.model] enabled = false, identify_s = 0`` (the nominal model only: the baseline),
and ``learning`` (``enabled = true, identify_s = 2``: the model correction and the flange load
estimate of :mod:`controller.arm_model`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

#: label -> [sim.plant] overrides (environment values, TOML syntax).
PLANTS: dict[str, dict[str, str]] = {
    "nominal": {},
    "+15 % links, +0.5 kg tool": {"MASS_SCALE": "1.15", "INERTIA_SCALE": "1.15", "TOOL_MASS_KG": "0.5"},
    "+30 % links, +1.0 kg tool": {"MASS_SCALE": "1.3", "INERTIA_SCALE": "1.3", "TOOL_MASS_KG": "1.0"},
    "stuerz2017 (identified link masses)": {"PROFILE": '"stuerz2017"'},
}
#: More plants (``--plants extra``): label -> [sim.plant] overrides.
EXTRA: dict[str, dict[str, str]] = {
    "nominal, measured state 3 periods late": {"STATE_DELAY_PERIODS": "3"},
    "random links +-30 %, CoM <= 2 cm, +1.5 kg tool (plant seed 1)": {
        "RANDOM_MASS_ERROR": "0.3", "RANDOM_COM_ERROR_M": "0.02", "TOOL_MASS_KG": "1.5", "SEED": "1"},
}
MODES = {"off": "false", "on": "true"}
#: A fitted load lighter than this [kg] is shown without its centre of mass.
NO_LOAD_KG = 0.05
#: controller label -> [controller.model] overrides (environment values).
CONTROLLERS = {"plain": {"ENABLED": "false", "IDENTIFY_S": "0"}, "learning": {"ENABLED": "true", "IDENTIFY_S": "2"}}


def run_cell(out: Path, seed: int, plant: dict[str, str], mode: str, skill: Path | None,
             controller: str = "learning") -> dict:
    """One network-free cell in ``out``; its report's figures (and the wall time it took)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("LAMPS__SIM__PLANT__")}
    env.update({f"LAMPS__SIM__PLANT__{k}": v for k, v in plant.items()})
    env["LAMPS__SIM__GRAVITY_COMPENSATED"] = MODES[mode]
    env = {k: v for k, v in env.items() if not k.startswith("LAMPS__CONTROLLER__MODEL__")}
    env.update({f"LAMPS__CONTROLLER__MODEL__{k}": v for k, v in CONTROLLERS[controller].items()})
    env["PYTHONPATH"] = str(REPO)
    argv = [sys.executable, "-m", "runtime.cli", "up", "--no-network", "--seed", str(seed), "--out", str(out),
            "-q", "--max-duration", "900"] + (["--skill", str(skill)] if skill is not None else [])
    t0 = time.monotonic()
    r = subprocess.run(argv, cwd=REPO, env=env, capture_output=True, text=True)
    wall = time.monotonic() - t0
    report = out / "report.json"
    if not report.exists():
        raise SystemExit(f"bench_plant: the cell in {out} wrote no report (exit {r.returncode}):\n{r.stderr[-3000:]}")
    rep = json.loads(report.read_text())
    return {"outcome": rep["outcome"], "final_phase": rep["final_phase"], "removed": rep["dirt_removed_fraction"],
            "force_mean_n": rep["normal_force_mean_n"], "force_std_n": rep["normal_force_std_n"],
            "force_max_n": rep["max_normal_force_n"], "tracking_rms_m": rep["tracking_rms_m"], "wall_s": wall,
            "arm_model": rep.get("arm_model", {})}


def _load(arm: dict) -> str:
    """The estimated flange load as a table cell: mass and centre of mass (flange frame), or a dash."""
    if not arm.get("tool_fitted"):
        return "-"
    c, m = arm["tool_com_m"], arm["tool_mass_kg"]
    if abs(m) < NO_LOAD_KG:  # a centre of mass of nothing is noise
        return f"{m:.2f} kg"
    return f"{m:.2f} kg at ({c[0] * 100:.1f}, {c[1] * 100:.1f}, {c[2] * 100:.1f}) cm"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", default="off,on", help="robot gravity compensation: off, on or off,on")
    ap.add_argument("--plants", choices=("main", "extra", "all"), default="main")
    ap.add_argument("--controllers", default="plain,learning", help="plain, learning or plain,learning")
    ap.add_argument("--json", type=Path, help="also write the figures as JSON")
    a = ap.parse_args()
    plants = {"main": PLANTS, "extra": EXTRA, "all": {**PLANTS, **EXTRA}}[a.plants]
    modes = [m.strip() for m in a.modes.split(",") if m.strip()]
    if not modes or any(m not in MODES for m in modes):
        ap.error(f"--modes takes {', '.join(MODES)} (comma separated), got {a.modes!r}")
    ctrls = [c.strip() for c in a.controllers.split(",") if c.strip()]
    if not ctrls or any(c not in CONTROLLERS for c in ctrls):
        ap.error(f"--controllers takes {', '.join(CONTROLLERS)} (comma separated), got {a.controllers!r}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-plant-") as tmp:
        skill = None
        for mode in modes:
            for i, (label, plant) in enumerate(plants.items()):
                for ctrl in ctrls:
                    out = Path(tmp) / f"{mode}-{i}-{ctrl}"
                    res = run_cell(out, a.seed, plant, mode, skill, ctrl)
                    if skill is None:
                        skill = out / "learn" / "skill.json"
                    rows.append({"plant": label, "gravity_compensated": mode == "on", "controller": ctrl, **res})
                    print(f"{label}, robot compensates {mode}, {ctrl}: {res['outcome']} {res['removed']:.1%} "
                          f"{res['tracking_rms_m'] * 1e3:.1f} mm ({res['wall_s']:.0f} s)", file=sys.stderr)
    print(f"The controller on simulated arms that are not its model (wall board, seed {a.seed}, lock-step, "
          f"network-free cell)\n")
    print("| simulated arm | robot compensates gravity | controller | outcome | removed | force while wiping "
          "(mean +- std) | max force | tracking RMS in contact | flange load estimated |\n"
          "|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['plant']} | {'yes' if r['gravity_compensated'] else 'no'} | {r['controller']} | {r['outcome']} | "
              f"{r['removed']:.1%} | {r['force_mean_n']:.1f} +- {r['force_std_n']:.1f} N | {r['force_max_n']:.1f} N | "
              f"{r['tracking_rms_m'] * 1e3:.1f} mm | {_load(r['arm_model']) if r['controller'] != 'plain' else '-'} |")
    print(f"\n{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    cmd = ".venv/bin/python bench/bench_plant.py" + (f" --seed {a.seed}" if a.seed else "") \
        + ("" if a.modes == "off,on" else f" --modes {a.modes}") \
        + ("" if a.plants == "main" else f" --plants {a.plants}") \
        + ("" if a.controllers == "plain,learning" else f" --controllers {a.controllers}")
    print(f"reproduce: {cmd}")
    if a.json:
        from lampskit.atomic import write_text_atomic

        write_text_atomic(a.json, json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
