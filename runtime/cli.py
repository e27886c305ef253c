"""The one console script, ``lamps``: dispatches to each package's entry point.

Each subcommand is ``"module:function"``, imported only when chosen, so
``lamps segment`` does not pay for PyBullet or Zenoh. Every entry point takes
its own argument list and returns an exit code.
"""

from __future__ import annotations

import importlib
import sys

#: subcommand -> (entry point, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("lampskit.cli:demo_main", "the embedded default: synthesize, learn, plot, save a skill"),
    "demo-data": ("lampskit.cli:demo_data_main", "write a synthetic multi-periodic wiping demonstration"),
    "segment": ("lampskit.cli:segment_main", "segment a demonstration into periodic and transitional MPs"),
    "evaluate-segmentation": (
        "lampskit.cli:evaluate_main",
        "frame accuracy of a segmentation against hand labels",
    ),
    "learn": ("launch.learn:learn_main", "segment and learn a demonstration into a skill file"),
    "plan": ("lampskit.cli:plan_main", "plan and roll out a skill over given stains"),
    "sim": ("sim.cli:main", "the simulated robot, board and camera as a Zenoh service"),
    "lbr-peer": ("sim.lbr_stack.cli:main", "a simulated iiwa behind lbr_fri_ros2_stack's keys, to test the adapter"),
    "robot": ("robot.cli:main", "a robot side over Zenoh: the real iiwa through lbr_fri_ros2_stack, or a mock arm"),
    "controller": ("controller.cli:main", "run a skill on the robot: impedance control and the skill executor"),
    "perception": ("perception.cli:main", "stains and kappa from camera images (board markers, ink clustering)"),
    "up": ("launch.cli:up_main", "the whole cell from docker-compose.yml as local processes, recorded and reported"),
    "teach": ("launch.teach:main", "hand-guide the arm (teach mode) and record the pad's path as a demonstration"),
    "record": (
        "launch.record_cli:record_main",
        "record every key into an MCAP file; report.json and plots when stopped",
    ),
    "foxglove": ("launch.live:main", "serve the running cell to the Foxglove app over its WebSocket protocol"),
    "report": ("launch.record_cli:report_main", "rebuild a run's report.json and plots from its recording"),
    "campaign": ("launch.campaign:main",
                 "many seeded cells, several at once: success, time against a lower bound, peaks"),
    "router": ("launch.router:main", "a Zenoh router with the cell's identities and access list (several hosts)"),
    "health": ("launch.health:main", "is this service ready (its Zenoh endpoints accept connections)? compose's probe"),
    "folders": ("launch.folders:main", "make the cell's host folders and give them to the service user (compose)"),
    "credentials": ("runtime.credentials:main",
                    "make a cell's CA and one mutual-TLS identity per role (the access list's subjects)"),
    "certificates": ("runtime.certificates:main",
                     "make a CA and certificates for other names (flat layout; --add signs one more)"),
    "bench": ("launch.bench:main", "run every benchmark into bench.json and a markdown page (a source checkout)"),
}


def version() -> str:
    """``lamps X.Y.Z`` with the versions of the middleware and the libraries a bug report needs."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as of

    def v(name: str) -> str:
        try:
            return of(name)
        except PackageNotFoundError:
            return "not installed"

    return (f"lamps {v('lamps')} (python {sys.version.split()[0]}, eclipse-zenoh {v('eclipse-zenoh')}, "
            f"pin {v('pin')}, pybullet {v('pybullet')}, numpy {v('numpy')})")


def _usage() -> str:
    width = max(len(name) for name in COMMANDS)
    lines = ["usage: lamps COMMAND [options]   (lamps COMMAND --help for each; lamps --version)", "",
             "commands:"]
    lines += [f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0 if args else 2
    if args[0] in ("-V", "--version"):
        print(version())
        return 0
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        print(f"lamps: unknown command {name!r}; valid: {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    module_name, func_name = COMMANDS[name][0].split(":")
    entry = getattr(importlib.import_module(module_name), func_name)
    return int(entry(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
