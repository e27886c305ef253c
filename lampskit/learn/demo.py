"""The demonstration: timestamps, tool positions and optional orientations.

A :class:`Demonstration` is validated once, when it is built; everything
downstream trusts it. Positions are in metres in whatever frame the
recording used (the robot base frame for the real demos); learning later
re-expresses them in the demonstration's own surface frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lampskit.errors import DemoError

#: Fewer samples than this cannot hold one periodic and one transitional MP.
MIN_SAMPLES = 50
#: A demonstration shorter than this (in seconds) is rejected for the same reason.
MIN_DURATION_S = 1.0


@dataclass(frozen=True)
class Demonstration:
    """One recorded tool trajectory.

    Attributes
    ----------
    t_s : array, shape (T,)
        Sample times [s], strictly increasing.
    position_m : array, shape (T, 3)
        Tool (eraser centre) position [m].
    orientation_wxyz : array, shape (T, 4) or None
        Tool orientation as unit quaternions, scalar first, or None when the
        recording has none.
    source : str
        Where it came from (file name or generator), for messages and plots.
    """

    t_s: np.ndarray
    position_m: np.ndarray
    orientation_wxyz: np.ndarray | None = None
    source: str = "<array>"

    def __post_init__(self) -> None:
        t = np.asarray(self.t_s, dtype=float)
        p = np.asarray(self.position_m, dtype=float)
        q = None if self.orientation_wxyz is None else np.asarray(self.orientation_wxyz, dtype=float)
        where = f"{self.source}: "
        if t.ndim != 1:
            raise DemoError(f"{where}timestamps must be a 1-D array, got shape {t.shape}")
        if p.ndim != 2 or p.shape[1] != 3:
            raise DemoError(f"{where}positions must have shape (T, 3), got {p.shape}")
        if len(t) != len(p):
            raise DemoError(f"{where}{len(t)} timestamps but {len(p)} positions")
        if len(t) == 0:
            raise DemoError(f"{where}the demonstration is empty (no samples)")
        if len(t) < MIN_SAMPLES:
            raise DemoError(f"{where}too short: {len(t)} samples, need at least {MIN_SAMPLES}")
        _check_finite(t[:, None], "timestamp", where)
        _check_finite(p, "position", where)
        steps = np.diff(t)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise DemoError(
                f"{where}timestamps must increase strictly: sample {i} has t={t[i]!r} "
                f"after t={t[i - 1]!r} ({bad.size} such step(s))"
            )
        if t[-1] - t[0] < MIN_DURATION_S:
            raise DemoError(
                f"{where}too short: {t[-1] - t[0]:.3f} s, need at least {MIN_DURATION_S} s"
            )
        if q is not None:
            if q.shape != (len(t), 4):
                raise DemoError(f"{where}orientations must have shape ({len(t)}, 4), got {q.shape}")
            _check_finite(q, "orientation", where)
            norms = np.linalg.norm(q, axis=1)
            if np.any(norms < 1e-6):
                raise DemoError(f"{where}orientation quaternion of zero norm at sample {int(np.argmin(norms))}")
            q = q / norms[:, None]
        for name, value in (("t_s", t), ("position_m", p), ("orientation_wxyz", q)):
            if value is not None:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_samples(self) -> int:
        return len(self.t_s)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    @property
    def rate_hz(self) -> float:
        """Mean sample rate [Hz]."""
        return (self.n_samples - 1) / self.duration_s

    def slice(self, start: int, end: int) -> Demonstration:
        """Samples ``[start, end)`` as a new demonstration (validated again)."""
        q = None if self.orientation_wxyz is None else self.orientation_wxyz[start:end]
        return Demonstration(self.t_s[start:end], self.position_m[start:end], q, f"{self.source}[{start}:{end}]")


def _check_finite(values: np.ndarray, what: str, where: str) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        kind = "NaN" if np.isnan(values[row]).any() else "inf"
        raise DemoError(
            f"{where}{what} is {kind} at sample {row} ({int(bad.any(axis=1).sum())} bad row(s)); "
            "every value must be finite"
        )
