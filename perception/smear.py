"""A smear is a state: a stain whose remaining ink stops falling over the eraser's passes.

On a real board a dry eraser leaves a grey smear where a dense drawing was
(a wipe made from a photograph with a ghost of a third of the drawing's
contrast reads 20-40 % remaining however often it is wiped). kappa never
comes, so an executor that waits for it re-passes the stain until its own
limit, and the report says only "not clean". :class:`SmearWatch` says
what it is: the camera sees a pass as the stain hidden (its visible share
below ``hidden_below``, the eraser and the arm over it) and back in view
(above ``seen_above``) with the pad's face on the board over the stain at
some frame since the last return (:func:`pad_over`; the arm crossing the
camera's view of it, wiping a stain beside it, hides it too: on random
board 303 eight such returns gave up a stain the pad had not touched as
smeared); where the pad is not known, every return counts. At each pass
the remaining is compared with the lowest one seen at an earlier pass; a
pass that lowers it by less than ``min_progress`` makes no progress, and ``passes`` passes in a row without
progress make the stain *smeared* (:class:`Smear`: the remaining, the
passes made). kappa, or progress again, ends it. Pure logic on the
per-stain fractions perception publishes; one watch per board.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import numpy as np

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


def pad_over(pad: tuple[np.ndarray, np.ndarray] | None, centre_m: np.ndarray, radius_m: float) -> bool:
    """Whether the pad's box on the board (low (2,), high (2,)) [m], or None (off the board), meets the stain's
    disc (``centre_m`` (2,), ``radius_m``) [m]."""
    if pad is None:
        return False
    lo, hi = pad
    nearest = np.clip(np.asarray(centre_m, float), lo, hi)
    return bool(np.linalg.norm(nearest - centre_m) <= radius_m)


@dataclass
class _Stain:
    best: float
    hidden: bool = False
    wiped: bool = False
    passes: int = 0
    stalls: int = 0
    remaining: float = 1.0


@dataclass
class SmearWatch:
    """Per stain id, its passes and whether it is smeared (module docstring); :meth:`update` once per stains
    message for each stain in it."""

    params: SmearParams = field(default_factory=SmearParams)
    _stains: dict[int, _Stain] = field(default_factory=dict)

    def update(self, stain_id: int, remaining: float, visible: float, kappa: bool,
               pad_on_it: bool | None = None) -> Smear | None:
        """The stain's :class:`Smear` after this observation, or None while it is not smeared; ``pad_on_it``:
        the pad's face on the board over the stain in this frame (None: not known, any return is a pass)."""
        p = self.params
        s = self._stains.get(stain_id)
        if s is None:
            s = self._stains[stain_id] = _Stain(best=remaining, remaining=remaining)
        s.wiped = s.wiped or pad_on_it is None or pad_on_it
        if visible < p.hidden_below:
            s.hidden = True
        elif s.hidden and visible >= p.seen_above:  # back in view: a pass if the pad was on it meanwhile
            s.hidden, wiped, s.wiped = False, s.wiped, False
            if not wiped:
                return self.smear(stain_id)
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
