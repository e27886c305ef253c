"""The periodic DMP's effective parameters y_m, r, Omega and stroke, and the filters moving them to their targets.

Each parameter follows its target through a critically damped second-order filter
``e'' = -w^2 e - 2 w e'`` (``e`` = value - target, ``w = 1 / tau``), stepped exactly,
so the effective parameters are C1 (:class:`ParameterRamp`).
"""

from __future__ import annotations

import math

import numpy as np


class ParameterRamp:
    """The effective y_m, r, Omega and stroke of a :class:`~lampskit.core.periodic_runner.PeriodicRunner`, their
    targets and their critically damped filters.

    Attributes
    ----------
    n_dims : int
    ym : array, shape (n_dims,)
        Effective y_m [m].
    r, omega : float
        Effective amplitude r [m] and frequency Omega [rad/s].
    has_stroke : bool
        A stroke was given: the forcing is mapped by :attr:`S` (without one the step skips the map).
    S : array, shape (n_dims, n_dims)
        Effective stroke (the identity when none was given); ``S_flat`` is its row-major view (n_dims^2,).
    targets : array, shape (n_dims + 2 + n_dims^2,)
        Columns: y_m [m] (n_dims), r [m], Omega [rad/s], the stroke's entries (row-major).
    ev, ev_next : arrays, shape (2, n_dims + 2 + n_dims^2)
        Filter state, double-buffered; rows: error (value - target), its rate [unit/s]; columns as :attr:`targets`.
    rate : float
        w = 1 / tau [rad/s] of the filters; 0: a new target is taken at once.
    filter_map : array, shape (2, 2)
        Exact step of the filters for ``filter_dt`` [s].
    delta : array, shape (n_dims,)
        How far y_m moved in the last step [m].
    settle_countdown : int
        Steps until the next check whether the filters have settled.
    ramping : bool
        Some parameter still moves toward its target.
    """

    __slots__ = ("n_dims", "ym", "r", "omega", "has_stroke", "S", "S_flat", "targets", "ev", "ev_next", "rate",
                 "filter_map", "filter_dt", "delta", "settle_countdown", "ramping")

    def __init__(self, anchor: np.ndarray, amp: float, omega: float, stroke: np.ndarray | None,
                 tau: float) -> None:
        n = anchor.shape[0]
        self.n_dims = n
        self.ym = anchor.copy()
        self.r, self.omega = amp, omega
        self.has_stroke = stroke is not None
        self.S = np.eye(n) if stroke is None else stroke.copy()
        self.S_flat = self.S.reshape(-1)  # a view
        self.targets = np.concatenate([anchor, [amp, omega], self.S_flat])
        self.ev = np.zeros((2, n + 2 + n * n))
        self.ev_next = np.zeros((2, n + 2 + n * n))
        self.rate = 0.0 if tau == 0 else 1.0 / tau
        self.filter_map = np.empty((2, 2))
        self.filter_dt = math.nan
        self.delta = np.empty(n)
        self.settle_countdown = 0
        self.ramping = False

    def retarget(self, anchor: np.ndarray | None, amplitude_m: float | None, omega_rad_s: float | None,
                 stroke: np.ndarray | None, x1: np.ndarray) -> None:
        """New targets (checked; None keeps one); with no filter (rate 0) taken at once, shifting ``x1`` =
        y1 - y_m (n_dims,) [m] so that y1 does not move."""
        n, targets = self.n_dims, self.targets
        if anchor is not None:
            targets[:n] = anchor
        if amplitude_m is not None:
            targets[n] = float(amplitude_m)
        if omega_rad_s is not None:
            targets[n + 1] = float(omega_rad_s)
        if stroke is not None:
            targets[n + 2:] = stroke.reshape(-1)
            self.has_stroke = True
        if self.rate == 0.0:  # no ramp: jump now
            self.snap(x1)
        else:
            self.ev[0, :n] = self.ym - targets[:n]
            self.ev[0, n] = self.r - targets[n]
            self.ev[0, n + 1] = self.omega - targets[n + 1]
            np.subtract(self.S_flat, targets[n + 2:], out=self.ev[0, n + 2:])
            self.ramping = True

    def advance(self, dt: float, x1: np.ndarray) -> None:
        """Exact step of the critically damped filters e'' = -w^2 e - 2 w e' (e = value - target) over ``dt`` [s].

        ``e(t) = (e0 + g t) exp(-w t)``, ``e'(t) = (e0' - w g t) exp(-w t)``, ``g = e0' + w e0``:
        one (2, 2) map applied to every column (y_m per dimension, r, Omega, the stroke's entries). ``x1`` =
        y1 - y_m (n_dims,) [m] shifts with y_m so that y1 does not move.
        """
        w = self.rate
        if dt != self.filter_dt:
            d = math.exp(-w * dt)
            self.filter_map[:] = [[d * (1.0 + w * dt), d * dt], [-d * w * w * dt, d * (1.0 - w * dt)]]
            self.filter_dt = dt
        ev, ev_next, n = self.ev, self.ev_next, self.n_dims
        np.matmul(self.filter_map, ev, out=ev_next)
        # y_m moves by delta; x1 = y1 - y_m shifts so that y1 does not move.
        np.subtract(ev_next[0, :n], ev[0, :n], out=self.delta)
        self.ym += self.delta
        x1 -= self.delta
        self.r = float(self.targets[n] + ev_next[0, n])
        self.omega = float(self.targets[n + 1] + ev_next[0, n + 1])
        if self.has_stroke:
            np.add(self.targets[n + 2:], ev_next[0, n + 2:], out=self.S_flat)
        self.ev, self.ev_next = ev_next, ev
        self.settle_countdown -= 1
        if self.settle_countdown <= 0:
            self.settle_countdown = 32
            scale = self.targets[n]  # amplitude for y_m and r, Omega for Omega
            err = np.abs(ev_next[0]) + np.abs(ev_next[1]) / w
            if err[: n + 1].max() < 1e-9 * scale and err[n + 1] < 1e-9 * self.targets[n + 1] \
                    and err[n + 2:].max() < 1e-9:
                self.snap(x1)

    def snap(self, x1: np.ndarray) -> None:
        """Every parameter at its target now, the filters at rest; ``x1`` = y1 - y_m (n_dims,) [m] shifted so that
        y1 does not move."""
        n, targets = self.n_dims, self.targets
        x1 -= targets[:n] - self.ym
        self.ym[:] = targets[:n]
        self.r, self.omega = float(targets[n]), float(targets[n + 1])
        self.S_flat[:] = targets[n + 2:]
        self.ev[:] = 0.0
        self.ramping = False
