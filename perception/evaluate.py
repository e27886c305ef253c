"""Perception's kappa against the simulator's truth: when each stain was really wiped, seen, and flagged.

Used by the closed-loop test and the benchmark; times are sim time [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from interfaces.messages import SimTruth, Stains

from .params import KappaParams


@dataclass(frozen=True)
class KappaTiming:
    """One stain: ``truth_index`` into the truth's stains; times [s], NaN when it never happened.

    truth_below_s : the truth's remaining first at or below the kappa level.
    in_view_s : first message after that with ``visible >= min_seen``.
    kappa_s : first message with kappa. truth_at_kappa : the truth's
    remaining then (NaN without kappa).
    """

    stain_id: int
    truth_index: int
    truth_below_s: float
    in_view_s: float
    kappa_s: float
    truth_at_kappa: float

    def describe(self, level: float) -> str:
        view = f"{self.in_view_s:.2f} s" if math.isfinite(self.in_view_s) else "never fully"
        kappa = (f"kappa at {self.kappa_s:.2f} s (truth then {self.truth_at_kappa:.1%})"
                 if math.isfinite(self.kappa_s) else "no kappa")
        return (f"stain {self.truth_index}: truth <= {level:.0%} at {self.truth_below_s:.2f} s, in view at {view}, "
                f"{kappa}")


def kappa_timings(sent: list[Stains], truths: list[SimTruth], params: KappaParams) -> list[KappaTiming]:
    """Per perceived stain, matched to the truth by nearest centre (lost-board messages ignored)."""
    msgs = [m for m in sent if m.board != "lost"]
    centres = np.array(truths[-1].centres_board_m)
    nan = float("nan")
    out = []
    for sid in sorted({s.id for m in msgs for s in m.stains}):
        obs = [(m.robot_time_ns * 1e-9, s) for m in msgs for s in m.stains if s.id == sid]
        k = int(np.argmin(np.linalg.norm(centres - obs[-1][1].centre_board_m, axis=1)))
        t_truth = next((t.robot_time_ns * 1e-9 for t in truths if t.remaining[k] <= params.level), nan)
        t_kappa = next((t for t, s in obs if s.kappa), nan)
        t_view = next((t for t, s in obs if t >= t_truth and s.visible >= params.min_seen), nan)
        at_kappa = (min(truths, key=lambda t: abs(t.robot_time_ns * 1e-9 - t_kappa)).remaining[k]
                    if math.isfinite(t_kappa) else nan)
        out.append(KappaTiming(sid, k, t_truth, t_view, t_kappa, float(at_kappa)))
    return out
