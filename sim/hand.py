"""The operator's hand on the tool, for teaching in the simulator: a scripted path followed through a spring.

A person guiding the arm in teach mode holds the tool and leads it; in the
simulator the hand is a script (``[sim.hand] script``), so teaching is a
test like any other:

- a path ``t,x,y,z`` (world frame [s, m]): the hand moves along it and pulls
  the pad centre p towards it through a spring-damper, the tool held at its
  start orientation R_0 by a rotational one::

      f = K_t (p_h(t) - p) + D_t (v_h(t) - v)        |f| <= max_force_n
      m = K_r log(R_0 R^T) - D_r w

  A path a few millimetres behind the board's face presses the pad on it
  with K_t times that depth (:func:`launch.teach_hand.hand_path` puts it
  there);
- a recorded force ``t,fx,fy,fz`` [s, N]: applied as it is (no feedback).

Either is linear in time between samples and holds its first and last
sample outside them. :class:`Hand` computes the wrench at the pad from the
last readout; :class:`~sim.robot.SimRobot` applies it for the next step.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from interfaces.errors import ConfigError

from .params import HandParams

PATH_COLUMNS = ("t", "x", "y", "z")
FORCE_COLUMNS = ("t", "fx", "fy", "fz")


class HandScript:
    """A hand script read from CSV: ``t`` (T,) [s] strictly increasing and ``values`` (T, 3), a path [m] or a
    force [N] (``is_force``). Raises :class:`ConfigError` naming the file and what is wrong."""

    def __init__(self, t_s: np.ndarray, values: np.ndarray, is_force: bool, source: str = "") -> None:
        t_s, values = np.asarray(t_s, float), np.asarray(values, float)
        where = source or "hand script"
        if t_s.ndim != 1 or values.shape != (len(t_s), 3) or len(t_s) < 2:
            raise ConfigError(f"{where}: need at least two rows of t and three values, got {values.shape}")
        if not (np.all(np.isfinite(t_s)) and np.all(np.isfinite(values))):
            raise ConfigError(f"{where}: non-finite values")
        if np.any(np.diff(t_s) <= 0.0):
            raise ConfigError(f"{where}: t must be strictly increasing")
        self.t_s, self.values, self.is_force = t_s, values, is_force
        self.velocity = np.gradient(values, t_s, axis=0) if not is_force else np.zeros_like(values)
        self._k = 0

    @classmethod
    def read(cls, path: str | Path) -> HandScript:
        path = Path(path)
        try:
            with open(path, newline="", encoding="utf-8") as f:
                rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
        except OSError as exc:
            raise ConfigError(f"[sim.hand] script {path}: {exc.strerror or exc}") from None
        if len(rows) < 3:
            raise ConfigError(f"[sim.hand] script {path}: a header and at least two rows needed")
        header = [c.strip().lower() for c in rows[0]]
        for cols, is_force in ((PATH_COLUMNS, False), (FORCE_COLUMNS, True)):  # noqa: B007 (read after the loop)
            if all(c in header for c in cols):
                break
        else:
            raise ConfigError(f"[sim.hand] script {path}: header {header} has neither {','.join(PATH_COLUMNS)} nor "
                              f"{','.join(FORCE_COLUMNS)}")
        idx = [header.index(c) for c in cols]
        try:
            data = np.array([[float(r[i]) for i in idx] for r in rows[1:]])
        except (ValueError, IndexError):
            raise ConfigError(f"[sim.hand] script {path}: a row is short or not numbers") from None
        return cls(data[:, 0], data[:, 1:], is_force, f"[sim.hand] script {path}")

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1])

    def at(self, t_s: float, out_value: np.ndarray, out_rate: np.ndarray) -> None:
        """Value (3,) and its rate (3,) at ``t_s`` into the outputs (the rate is 0 outside the script); a cursor
        makes the usual forward stepping O(1)."""
        t = self.t_s
        if t_s <= t[0] or t_s >= t[-1]:
            out_value[:] = self.values[0 if t_s <= t[0] else -1]
            out_rate[:] = 0.0
            return
        k = self._k if t[self._k] <= t_s else 0
        while t[k + 1] < t_s:
            k += 1
        self._k = k
        a = (t_s - t[k]) / (t[k + 1] - t[k])
        out_value[:] = (1.0 - a) * self.values[k] + a * self.values[k + 1]
        out_rate[:] = (1.0 - a) * self.velocity[k] + a * self.velocity[k + 1]


class Hand:
    """The hand's wrench on the pad from a :class:`HandScript` (see the module docstring).

    R_hold : (3, 3) the orientation the hand holds the tool in (the tool's at the start).
    """

    def __init__(self, params: HandParams, script: HandScript, R_hold: np.ndarray) -> None:
        self.p = params
        self.script = script
        self.R_hold = np.array(R_hold, float)
        self.wrench = np.zeros(6)
        self.target_m = np.zeros(3)
        self._rate = np.zeros(3)

    def update(self, t_s: float, p: np.ndarray, v: np.ndarray, R: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The wrench (6,) [N, Nm] (world axes, at the pad centre) the hand puts on the tool at time ``t_s`` [s],
        for the pad at ``p`` (3,) [m] moving at ``v`` (3,) [m/s], orientation ``R`` (3, 3), spin ``w`` (3,)."""
        hp, f = self.p, self.wrench[:3]
        self.script.at(t_s, self.target_m, self._rate)
        if self.script.is_force:
            f[:] = self.target_m
        else:
            f[:] = hp.stiffness_n_m * (self.target_m - p) + hp.damping_n_s_m * (self._rate - v)
        norm = math.sqrt(float(f @ f))
        if norm > hp.max_force_n:
            f *= hp.max_force_n / norm
        self.wrench[3:] = hp.stiffness_nm_rad * rotation_vector(self.R_hold @ R.T) - hp.damping_nm_s_rad * w
        return self.wrench


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """(3,) axis times angle [rad] of the rotation matrix ``R`` (3, 3), angle in [0, pi)."""
    c = min(max((np.trace(R) - 1.0) / 2.0, -1.0), 1.0)
    angle = math.acos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = math.sin(angle)
    return v * (0.5 if s < 1e-9 else angle / (2.0 * s))


def hand_from_params(params: HandParams, R_hold: np.ndarray) -> Hand | None:
    """The configured hand, or None without a script."""
    if not params.script:
        return None
    return Hand(params, HandScript.read(params.script), R_hold)
