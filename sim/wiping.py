"""The pad wiping the dirt: which steps wipe, whether the pad lies flat, and the pad's motion in the board frame.

:class:`PadWiper` turns a :class:`~sim.robot.Readout` (world frame) into one
:meth:`~sim.dirt.DirtGrid.wipe` call (board frame) every
``[sim.dirt] wipe_every_steps`` physics steps, with the slide of that
interval.
"""

from __future__ import annotations

import math

from arm.description import PAD_SIZE_M

from .board import Board
from .dirt import DirtGrid
from .params import DirtParams
from .robot import Readout


class PadWiper:
    """The pad's removal of the dirt on the board, every few physics steps.

    board : the board (its frame: origin [m], rotation ``R`` (3, 3) board to world, outward normal (3,) world).
    dirt : the grid the pad wipes. every_steps : physics steps per wipe; dt_s : the time one wipe covers
    (``every_steps`` physics steps) [s]. threshold_force_n : normal force [N] below which nothing is removed;
    rate_per_n_m : removal rate [1/(N m)]. cos_tilt : cosine of the largest tilt of the pad's normal from the
    board's at which the pad lies flat. half_pad_m : (half length, half width) of the pad [m].
    """

    __slots__ = ("board", "dirt", "every_steps", "dt_s", "threshold_force_n", "rate_per_n_m", "cos_tilt",
                 "half_pad_m")

    def __init__(self, board: Board, dirt: DirtGrid, params: DirtParams, dt_s: float) -> None:
        self.board = board
        self.dirt = dirt
        self.every_steps = params.wipe_every_steps
        self.dt_s = dt_s * params.wipe_every_steps
        self.threshold_force_n = params.threshold_force_n
        self.rate_per_n_m = params.rate_per_n_m
        self.cos_tilt = math.cos(math.radians(params.max_tilt_deg))
        self.half_pad_m = (PAD_SIZE_M[0] / 2, PAD_SIZE_M[1] / 2)

    def wipe(self, o: Readout) -> None:
        """Remove the dirt under the pad of readout ``o`` over the last ``every_steps`` steps: only while it presses
        harder than the threshold and lies flat (tilted, only an edge touches)."""
        if o.normal_force_n <= self.threshold_force_n:
            return
        board = self.board
        R = board.R
        tool_z = o.tcp_R[:, 2]
        if -(tool_z @ board.normal_world) < self.cos_tilt:
            return  # tilted: only an edge touches
        centre = (o.tcp_p - board.origin_m) @ R
        axis = o.tcp_R[:, 0] @ R[:, :2]
        norm = math.hypot(axis[0], axis[1])
        vel = o.tcp_v @ R[:, :2]
        spin = float(o.tcp_w @ R[:, 2])
        self.dirt.wipe(centre[:2], axis / norm, self.half_pad_m, vel, spin, o.normal_force_n,
                       self.dt_s, self.threshold_force_n, self.rate_per_n_m)
