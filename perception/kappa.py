"""kappa, the completion flag of one stain (paper III-C: 1 when the stain's dark pixels are gone), debounced.

Pure logic on times in seconds; one :class:`KappaLatch` per stain.
"""

from __future__ import annotations

from .params import KappaParams


class KappaLatch:
    """kappa of one stain from its remaining fraction and how much of it has been seen.

    Turns 1 once ``remaining <= level`` has held for ``debounce_s`` with the
    evidence good (``seen >= min_seen``) all along; back to 0 only after
    ``remaining > level + reappear_margin`` has held for ``debounce_s`` with
    good evidence. A frame without good evidence restarts either count:
    what is not seen never counts as clean, nor as dirty again.
    """

    def __init__(self, params: KappaParams) -> None:
        self.p = params
        self.kappa = False
        self._since: float | None = None  # start of the current run towards a change of kappa

    def update(self, t_s: float, remaining: float, seen: float) -> bool:
        """kappa after the observation at ``t_s`` [s]; ``remaining`` and ``seen`` are fractions in [0, 1]."""
        p = self.p
        evidence = seen >= p.min_seen
        towards_change = evidence and (remaining > p.level + p.reappear_margin if self.kappa
                                       else remaining <= p.level)
        if not towards_change:
            self._since = None
            return self.kappa
        if self._since is None:
            self._since = t_s
        if t_s - self._since >= p.debounce_s - 1e-9:
            self.kappa = not self.kappa
            self._since = None
        return self.kappa
