"""Write the random boards ``random:s`` as board TOML files, one per seed, for a controller whose sampler differs.

Usage: .venv/bin/python bench/random_board_files.py --seeds 0-999 --out DIR

Writes ``DIR/bNNN.toml`` (a ``[board]`` table: preset ``custom``,
``origin_m``, ``quat_wxyz``, ``size_m``, what ``lamps up --board FILE``
reads), atomically. A campaign at another commit given these files
(``--boards DIR/b000.toml,...,DIR/b999.toml``: seed s takes file s) runs
the very boards of this commit's ``--boards random``, and the same stains
(they follow from the seed and the board's table); this is how the
baseline of docs/campaigns.md#1000-boards runs a commit from before the
sampler kept only the boards the controller takes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lampskit.atomic import write_text_atomic  # noqa: E402


def board_toml(table: dict) -> str:
    """The ``[board]`` TOML of a random board's table (keys preset, origin_m, quat_wxyz, size_m)."""
    lines = ["[board]"]
    for key, value in table.items():
        if isinstance(value, str):
            lines.append(f'{key} = "{value}"')
        else:
            lines.append(f"{key} = [{', '.join(repr(float(v)) for v in value)}]")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from launch.campaign_cells import CampaignError, parse_range
    from sim.board_sampler import random_board_table

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", required=True, help="seeds, e.g. 0-999 or 3,5,9")
    ap.add_argument("--out", required=True, type=Path, help="folder for the bNNN.toml files (made if missing)")
    a = ap.parse_args(argv)
    try:
        seeds = parse_range(a.seeds, "--seeds")
    except CampaignError as exc:
        print(f"random_board_files: {exc}", file=sys.stderr)
        return 2
    a.out.mkdir(parents=True, exist_ok=True)
    for s in seeds:
        write_text_atomic(a.out / f"b{s:03d}.toml", board_toml(random_board_table(f"random:{s}")))
    print(f"wrote {len(seeds)} board files into {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
