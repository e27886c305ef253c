"""The controller's trace: the last ticks of reference and measurement, preallocated (published in batches)."""

from __future__ import annotations

import numpy as np

from interfaces.messages import Phase

#: Columns of the trace (see :class:`Trace`).
TRACE_COLUMNS = ("t_s", "phase", "ref_x", "ref_y", "ref_vx", "ref_vy", "ref_ax", "ref_ay", "x", "y", "h",
                 "ref_p_x", "ref_p_y", "ref_p_z", "p_x", "p_y", "p_z", "force_n", "press_n", "contact",
                 "speed_scale")
#: Trace code of each phase name: its place in :class:`~interfaces.messages.Phase`.
PHASE_CODES = {phase.value: i for i, phase in enumerate(Phase)}


class Trace:
    """The last ``n`` ticks of reference and measurement, preallocated (no allocation per tick).

    Columns :data:`TRACE_COLUMNS`: time [s], phase code (:data:`PHASE_CODES`),
    in-plane reference (board frame) position/velocity/acceleration, measured
    board-frame pad position, world reference and measured positions [m],
    measured normal force and commanded press force [N], contact flag, the
    skill's time scale (:class:`~controller.control.limits.SpeedOverride`; on
    a cycle the robot held, the arm's own progress along the path);
    the reference's rates are as executed (time-scaled).
    """

    def __init__(self, n: int) -> None:
        self.data = np.zeros((n, len(TRACE_COLUMNS)))
        self.n = 0

    def row(self) -> np.ndarray:
        r = self.data[self.n % len(self.data)]
        self.n += 1
        return r

    def since(self, tick: int) -> tuple[int, np.ndarray, int]:
        """Rows from ``tick`` (a count of rows ever written) on: (first tick, rows in time order, rows lost)."""
        m = len(self.data)
        first = max(tick, self.n - m)
        idx = np.arange(first, self.n) % m
        return first, self.data[idx], first - tick

    def array(self) -> np.ndarray:
        """(m, len(TRACE_COLUMNS)) in time order."""
        m = len(self.data)
        if self.n <= m:
            return self.data[: self.n].copy()
        i = self.n % m
        return np.vstack([self.data[i:], self.data[:i]])
