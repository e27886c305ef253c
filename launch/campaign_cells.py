"""A campaign's cells (:mod:`launch.campaign`): one seeded board each, with its stain count, board and wiping mode,
how they are picked from ``--seeds``, ``--stains``, ``--boards`` and ``--wiping``, and the campaign's error."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from lampskit.errors import LampsError

WIPINGS = ("fixed", "adaptive")


class CampaignError(LampsError):
    """A clear, one-line reason why the campaign could not run."""


@dataclass(frozen=True)
class Cell:
    """One seeded board: ``seed``, ``stains`` (count), ``board`` (preset name or TOML file), ``wiping`` mode,
    ``plant`` (the simulated arm, :mod:`launch.campaign_plants`); ``plots``: whether its run draws the report's
    plots (not part of what the cell is: ``lamps report`` draws them later from its recording)."""

    seed: int
    stains: int
    board: str
    wiping: str = "fixed"
    plots: bool = field(default=False, compare=False)
    plant: str = "nominal"

    @property
    def name(self) -> str:
        suffix = "-adaptive" if self.wiping == "adaptive" else ""
        if self.plant != "nominal":
            suffix += f"-{self.plant}"
        board = "random" if self.board.startswith("random:") else Path(self.board).stem
        return f"{board}-s{self.seed}-n{self.stains}{suffix}"


def parse_range(text: str, what: str) -> list[int]:
    """``"0-49"``, ``"3"`` or ``"1,4,7-9"`` as a sorted list of distinct non-negative integers."""
    out: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        try:
            lo, _, hi = part.partition("-")
            a, b = int(lo), int(hi) if hi else int(lo)
        except ValueError:
            raise CampaignError(f"--{what} {text!r}: {part!r} is not N or N-M (non-negative integers)") from None
        if a < 0 or b < a:
            raise CampaignError(f"--{what} {text!r}: {part!r} must satisfy 0 <= N <= M")
        out.update(range(a, b + 1))
    return sorted(out)


def cells_of(seeds: list[int], stains: list[int], boards: list[str], wipings: tuple[str, ...] = ("fixed",),
             plots: bool = False, plants: tuple[str, ...] = ("nominal",)) -> list[Cell]:
    """The campaign's cells: seed s gets ``stains[s mod len]`` stains on ``boards[s mod len]``, once per wiping
    mode and plant (board ``random``: seed s's own random board, ``random:s``); ``plots``: each run draws its
    report's plots."""
    from .campaign_plants import PLANTS

    if not seeds or not stains or not boards or not wipings or not plants:
        raise CampaignError("a campaign needs at least one seed, one stain count, one board, one wiping mode and "
                            "one plant")
    bad = [w for w in wipings if w not in WIPINGS]
    if bad:
        raise CampaignError(f"--wiping: {bad[0]!r} is not one of {WIPINGS}")
    bad = [p for p in plants if p not in PLANTS]
    if bad:
        raise CampaignError(f"--plants: {bad[0]!r} is not one of {PLANTS}")
    def board(s: int) -> str:
        b = boards[s % len(boards)]
        return f"random:{s}" if b == "random" else b

    return [Cell(s, stains[s % len(stains)], board(s), w, plots, p) for s in seeds for w in wipings for p in plants]
