"""Which stains the skill executor still has to wipe, and when it may wipe each again.

A camera cannot see a stain under the eraser, so a stain left without
kappa after a pass is passed over until ``recheck_s`` after that pass
(perception looks at it meanwhile) and wiped again after the others (it
is open only while no stain with fewer passes is: kappa often comes
seconds after the pad has left, once the arm no longer hides the stain,
and a stain wiped clean but not yet confirmed should not be wiped again
while others wait), at most ``max_passes`` times; then it is given up.

A stain perception reports smeared (:mod:`perception.smear`: the camera's
passes over it no longer lower its remaining ink) is closed as smeared once
perception has judged a pass of the executor's own over it: the report
counts more passes than perception had counted when that pass ended (the
pad's pass is counted when the stain is back in view). It is then not wiped
again, and :attr:`StainBook.smeared` keeps it, with its remaining and
passes, for the status and the report. A report made of other passes (the
arm hiding the stain on its way to others, or wiping a neighbour) is not
taken: on random board 322 the arm hid a stain three times while wiping
the others, perception called it smeared, and the executor's first real
pass (which took half its dirt) closed it. A stain the
arm cannot reach is closed the same way before any pass
(:meth:`StainBook.close_out_of_reach`, with the reason).
"""

from __future__ import annotations

import math
from collections import Counter

from lampskit.core.planner_types import Stain


class StainBook:
    """The stains last seen and the passes made over them.

    Parameters
    ----------
    recheck_s : float
        Time [s] after a pass without kappa before the stain is open again.
    max_passes : int
        Passes without kappa after which a stain is given up.

    Attributes
    ----------
    stains : dict of int to Stain
        The last view, by stain id.
    smeared : dict of int to Stain
        The stains closed as smeared, as they were when closed, by id.
    out_of_reach : dict of int to str
        The stains closed as out of the arm's reach, with why, by id.
    """

    def __init__(self, recheck_s: float, max_passes: int) -> None:
        self.recheck_s = recheck_s
        self.max_passes = max_passes
        self.stains: dict[int, Stain] = {}
        self._given_up: set[int] = set()
        self._passes: Counter[int] = Counter()
        self._left_at: dict[int, float] = {}  # stain id -> clock [s] at the end of a pass without kappa
        self._seen_passes_at_end: dict[int, int] = {}  # stain id -> perception's passes when our last pass ended
        self.smeared: dict[int, Stain] = {}
        self.out_of_reach: dict[int, str] = {}

    def update(self, stains: list[Stain], clock_s: float) -> bool:
        """A fresh view of the stains (kappa per stain): True if it changes which are open at ``clock_s`` [s]."""
        old_open = self.open_ids(clock_s)
        self.stains = {s.id: s for s in stains}
        for s in stains:
            if s.smeared and not s.kappa and s.id not in self.smeared and self._passes[s.id] >= 1 \
                    and s.passes > self._seen_passes_at_end.get(s.id, s.passes):
                self.smeared[s.id] = s  # perception has judged our last pass over it
        return self.open_ids(clock_s) != old_open

    def is_done(self, stain_id: int) -> bool:
        """The stain has kappa, is no longer seen, or was closed (smeared, out of reach)."""
        s = self.stains.get(stain_id)
        return s is None or s.kappa or stain_id in self.smeared or stain_id in self.out_of_reach

    def close_out_of_reach(self, stain_id: int, why: str) -> None:
        """The arm cannot reach the stain (``why``): it is never wiped."""
        self.out_of_reach[stain_id] = why

    def _closed(self, stain_id: int) -> bool:
        return stain_id in self._given_up or stain_id in self.smeared or stain_id in self.out_of_reach

    def end_pass(self, stain_id: int, clock_s: float) -> bool:
        """A pass over the stain ended without kappa at ``clock_s`` [s]: True if that was its last.

        The stain waits ``recheck_s``; after ``max_passes`` it is given up.
        """
        self._passes[stain_id] += 1
        self._left_at[stain_id] = clock_s
        seen = self.stains.get(stain_id)
        self._seen_passes_at_end[stain_id] = seen.passes if seen is not None else 0
        if self._passes[stain_id] >= self.max_passes:
            self._given_up.add(stain_id)
            return True
        return False

    def left_undone(self) -> str:
        """Why the stains without kappa that are closed are left ("" none), each by perception's id and its centre on
        the board: out of the arm's reach (the reason), smeared, or given up after ``max_passes`` passes; the reason
        of a DONE that leaves them."""
        parts = []
        for i, s in sorted(self.stains.items()):
            if s.kappa:
                continue
            at = f"stain {i} at ({s.centre_m[0]:.2f}, {s.centre_m[1]:.2f}) m"  # perception's id: where, to match it
            if i in self.out_of_reach:
                parts.append(f"{at} out of the arm's reach ({self.out_of_reach[i]})")
            elif i in self.smeared:
                parts.append(f"{at} smeared after {self._passes[i]} passes")
            elif i in self._given_up:
                parts.append(f"{at} given up after {self._passes[i]} passes")
        return f"{len(parts)} stain(s) left: " + "; ".join(parts) if parts else ""

    def passes(self, stain_id: int) -> int:
        """Passes over the stain that ended without kappa."""
        return self._passes[stain_id]

    def open_stains(self, clock_s: float, by_ink: bool = False, exclude: int | None = None) -> list[Stain]:
        """The stains to wipe at ``clock_s`` [s]: without kappa, not given up, not waiting for a recheck, not
        ``exclude`` (the stain just left), and of those the ones passed over least often (a stain is wiped again
        only after the others).

        ``by_ink``: a stain whose remaining ink perception reports is given by that ink's shape (centre, size,
        width, axis), not the whole stain's (adaptive wiping: a stain wiped before is planned for what is left).
        """
        ready = [s for s in self.stains.values()
                 if not s.kappa and not self._closed(s.id) and s.id != exclude
                 and clock_s - self._left_at.get(s.id, -math.inf) >= self.recheck_s]
        fewest = min((self._passes[s.id] for s in ready), default=0)
        return [s.ink if by_ink and s.ink is not None else s for s in ready if self._passes[s.id] == fewest]

    def open_ids(self, clock_s: float) -> set[int]:
        return {s.id for s in self.open_stains(clock_s)}

    def pending(self) -> list[Stain]:
        """Stains passed over without kappa, waiting to be looked at (not given up)."""
        return [s for i, s in self.stains.items() if not s.kappa and i in self._left_at and not self._closed(i)]

    def looked_at(self, clock_s: float) -> None:
        """The camera has a clear view of the pending stains from ``clock_s`` [s] on: their recheck starts again."""
        for s in self.pending():
            self._left_at[s.id] = clock_s
