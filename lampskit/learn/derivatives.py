"""Uniform resampling and smoothed derivatives of recorded trajectories.

Recorded demonstrations have jittery sample times and sensor noise; the
movement primitives need position, velocity and acceleration. We resample
to a uniform grid (linear interpolation, which is exact for the timestamps
we keep and harmless at 100-200 Hz) and differentiate with a
Savitzky-Golay filter (a local cubic fit), which smooths and
differentiates in one pass without phase lag.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from lampskit.errors import DemoError


def resample_uniform(t_s: np.ndarray, y: np.ndarray, rate_hz: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Resample ``y(t)`` onto a uniform time grid.

    Parameters
    ----------
    t_s : array, shape (T,)
        Strictly increasing sample times [s].
    y : array, shape (T, n_dims)
        Samples.
    rate_hz : float, optional
        Output rate [Hz]; default the mean input rate.

    Returns
    -------
    t_u : array, shape (T_u,)
        Uniform times starting at ``t_s[0]`` [s].
    y_u : array, shape (T_u, n_dims)
        Linearly interpolated samples.
    """
    t_s = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    duration = t_s[-1] - t_s[0]
    if rate_hz is None:
        rate_hz = (len(t_s) - 1) / duration
    if not rate_hz > 0:
        raise DemoError(f"resampling rate must be positive, got {rate_hz!r} Hz")
    n = int(np.floor(duration * rate_hz + 1e-9)) + 1
    t_u = t_s[0] + np.arange(n) / rate_hz
    y_u = np.column_stack([np.interp(t_u, t_s, y[:, d]) for d in range(y.shape[1])])
    return t_u, y_u


def smooth_derivatives(
    y: np.ndarray, dt_s: float, window_s: float = 0.08, polyorder: int = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed position, velocity and acceleration of a uniformly sampled signal.

    Parameters
    ----------
    y : array, shape (T, n_dims)
        Uniformly sampled positions [m].
    dt_s : float
        Sample period [s].
    window_s : float
        Savitzky-Golay window length [s] (rounded to an odd sample count,
        at least ``polyorder + 2`` samples, at most the signal length).
    polyorder : int
        Degree of the local polynomial.

    Returns
    -------
    pos, vel, acc : arrays, shape (T, n_dims)
        In [m], [m/s], [m/s^2].
    """
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    n = len(y)
    win = int(round(window_s / dt_s)) | 1
    win = max(win, polyorder + 2 + (polyorder + 2 + 1) % 2)
    if win > n:
        win = n if n % 2 else n - 1
    if win <= polyorder:
        raise DemoError(f"signal of {n} samples is too short to differentiate (need > {polyorder + 1})")
    kw = dict(window_length=win, polyorder=polyorder, axis=0, mode="interp")
    pos = savgol_filter(y, deriv=0, **kw)
    vel = savgol_filter(y, deriv=1, delta=dt_s, **kw)
    acc = savgol_filter(y, deriv=2, delta=dt_s, **kw)
    return pos, vel, acc
