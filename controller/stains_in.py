"""What the controller takes from a stains message: the board pose and the executor's view of each stain (pure).

Perception's :class:`~interfaces.messages.Stains` (``board = "lost"``:
nothing is known, not even what is clean) or, with ``stains_from =
"truth"``, the sim's :class:`~interfaces.messages.SimTruth` (a stain is
done at ``kappa_remaining`` of its dirt). A message the executor cannot use
is counted by reason in ``counters`` and gives None.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np

from interfaces.messages import SimTruth, StainObservation, Stains
from interfaces.transforms import transform_from_pose
from lampskit.core.planner_types import Stain
from lampskit.errors import PlanningError

from .executor_types import BoardPose


def stains_update(msg: Stains | SimTruth, kappa_remaining: float,
                  counters: Counter[str]) -> tuple[BoardPose, list[Stain]] | None:
    """``(board pose, stains)`` of ``msg``, or None (counted) when it holds nothing usable."""
    if isinstance(msg, SimTruth):
        if msg.T_board_to_world is None or len(msg.centres_board_m) != len(msg.stain_ids):
            counters["truth_without_board"] += 1
            return None
        board = BoardPose.from_transform(transform_from_pose(msg.T_board_to_world), (0.0, 0.0))
        if len(msg.sizes_m) != len(msg.stain_ids):
            counters["stains_rejected: truth sizes do not match its ids"] += 1
            return None
        return _with_stains(board, lambda: [Stain(i, np.asarray(c, float), float(s), kappa=r <= kappa_remaining)
                                            for i, c, s, r in zip(msg.stain_ids, msg.centres_board_m, msg.sizes_m,
                                                                  msg.remaining)], counters)
    if msg.board == "lost":
        counters["stains_unknown"] += 1
        return None
    board = BoardPose.from_transform(transform_from_pose(msg.T_board_to_world), msg.board_size_m, msg.camera_world_m)
    return _with_stains(board, lambda: [stain_state(s) for s in msg.stains], counters)


def _with_stains(board: BoardPose, make: Callable[[], list[Stain]],
                 counters: Counter[str]) -> tuple[BoardPose, list[Stain]] | None:
    """``(board, make())``, or None (counted) when a stain is not one (:class:`Stain` checks itself)."""
    try:
        return board, make()
    except PlanningError:
        counters["stains_rejected: a stain needs a finite 2-D centre and a positive size"] += 1
        return None


def stain_state(s: StainObservation) -> Stain:
    """The executor's view of one observed stain: centre, size, width and axis, kappa, the ink left (if reported)
    and a smear."""
    ink = None
    if len(s.ink_centre_board_m) == 2 and s.ink_size_m > 0:
        ink = Stain(s.id, np.asarray(s.ink_centre_board_m, float), s.ink_size_m, s.ink_width_m, s.ink_axis_board_rad)
    return Stain(s.id, np.asarray(s.centre_board_m, float), s.size_m, s.width_m, s.axis_board_rad, kappa=s.kappa,
                 ink=ink, smeared=s.smeared, remaining=s.remaining, passes=s.passes)
