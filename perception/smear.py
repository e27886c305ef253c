"""A smear is a state: a stain whose remaining ink stops falling over the eraser's passes.

On a real board a dry eraser leaves a grey smear where a dense drawing was
(a wipe made from a photograph with a ghost of a third of the drawing's
contrast reads 20-40 % remaining however often it is wiped). kappa never
comes, so an executor that waits for it re-passes the stain until its own
limit, and the report says only "not clean". :class:`SmearWatch` says
what it is: the camera sees a pass as the stain hidden (its visible share
below ``hidden_below``, the eraser and the arm over it) and back in view
(above ``seen_above``); at each return the remaining is compared with the
lowest one seen at an earlier return; a pass that lowers it by less than
``min_progress`` makes no progress, and ``passes`` passes in a row without
progress make the stain *smeared* (:class:`Smear`: the remaining, the
passes made). kappa, or progress again, ends it. Pure logic on the
per-stain fractions perception publishes; one watch per board.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from runtime.config import In, check_declared


@dataclass(frozen=True)
class SmearParams:
    """passes : passes in a row without progress that make a smear. min_progress : a pass that lowers the
    remaining fraction by less than this makes no progress. hidden_below / seen_above : the stain's visible
    share under which it is being wiped, and over which it is back in view (one pass)."""

    passes: Annotated[int, In(1, 100)] = 3
    min_progress: Annotated[float, In(0.0, 1.0)] = 0.05
    hidden_below: Annotated[float, In(0.0, 1.0)] = 0.5
    seen_above: Annotated[float, In(0.0, 1.0)] = 0.9

    def __post_init__(self) -> None:
        check_declared(self, "perception.smear")


@dataclass(frozen=True)
class Smear:
    """A stain that stopped getting cleaner: its id, its remaining fraction and the passes seen so far."""

    stain_id: int
    remaining: float
    passes: int


@dataclass
class _Stain:
    best: float
    hidden: bool = False
    passes: int = 0
    stalls: int = 0
    remaining: float = 1.0


@dataclass
class SmearWatch:
    """Per stain id, its passes and whether it is smeared (module docstring); :meth:`update` once per stains
    message for each stain in it."""

    params: SmearParams = field(default_factory=SmearParams)
    _stains: dict[int, _Stain] = field(default_factory=dict)

    def update(self, stain_id: int, remaining: float, visible: float, kappa: bool) -> Smear | None:
        """The stain's :class:`Smear` after this observation, or None while it is not smeared."""
        p = self.params
        s = self._stains.get(stain_id)
        if s is None:
            s = self._stains[stain_id] = _Stain(best=remaining, remaining=remaining)
        if visible < p.hidden_below:
            s.hidden = True
        elif s.hidden and visible >= p.seen_above:  # back in view: one pass made
            s.hidden = False
            s.passes += 1
            s.remaining = remaining
            if remaining <= s.best - p.min_progress:
                s.best, s.stalls = remaining, 0
            else:
                s.stalls += 1
        if kappa:
            s.stalls = 0
        return self.smear(stain_id)

    def smear(self, stain_id: int) -> Smear | None:
        """The stain's :class:`Smear` if it is smeared, else None."""
        s = self._stains.get(stain_id)
        if s is None or s.stalls < self.params.passes:
            return None
        return Smear(stain_id, s.remaining, s.passes)

    def passes(self, stain_id: int) -> int:
        """Passes the camera saw over the stain (0 for a stain never seen)."""
        s = self._stains.get(stain_id)
        return 0 if s is None else s.passes

    def smeared(self) -> list[Smear]:
        """Every smeared stain, by id."""
        return [m for i in sorted(self._stains) if (m := self.smear(i)) is not None]
