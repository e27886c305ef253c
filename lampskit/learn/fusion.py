"""One skill from several demonstrations: repeated MPs fused by GMM-GMR over all of them, with their spread.

A person shows the same skill more than once (the same wiping phases in the
same order on the same board); each demonstration is segmented on its own
and its MPs are matched by order (the k-th wiping phase of every demo is one
periodic MP, the k-th learned transition one transitional MP). A different
number of either is an error naming the demonstrations.

* **Periodic** (:func:`fuse_periodic`): each segment is phase-labelled as for
  one demo (:func:`~.periodic_fit.phase_labelled`) and gives its own GMR
  template; those are aligned to the first one's phase (the circular shift
  with the least squared difference, after removing each one's centre),
  and every demo's samples, shifted by that phase and moved onto the mean
  centre, feed *one* mixture: the fused template is E[y | phase] over all
  of them. Frequency and cycles are the demos' means.
* **Transitional** (:func:`fuse_transitional`): each segment is resampled on
  normalised time ``s = (t - t0) / T`` in [0, 1] and taken relative to its
  own start (demonstrations recorded in different places still agree on the
  move); a Gaussian mixture over ``(s, y - y(0))`` of all of them
  (scikit-learn, full covariances) gives by regression the mean move
  ``E[y - y(0) | s]``, which, from the mean start, is learned as a transition
  of the mean duration (:func:`~.transitional_fit.learn_transitional`).
* **Spread**, per MP, is what varied between demonstrations: the RMS and the
  largest (over phase or ``s``) standard deviation of the aligned paths
  around the fused one [m], and the standard deviations of frequency [Hz],
  centre [m] and amplitude [m] (periodic) or of start [m] and duration [s]
  (transitional).

Pure numpy / scikit-learn; no I/O.
"""

from __future__ import annotations

import numpy as np

from lampskit.core.periodic import DEFAULT_ALPHA, DEFAULT_N_BASIS, TWO_PI, PeriodicMP
from lampskit.core.transitional import TransitionalMP
from lampskit.errors import LearningError
from lampskit.learn.gmr import periodic_template
from lampskit.learn.periodic_fit import (
    DEFAULT_N_COMPONENTS,
    DEFAULT_N_TEMPLATE,
    MAX_GMM_SAMPLES,
    mp_from_template,
    phase_labelled,
)
from lampskit.learn.transitional_fit import learn_transitional

Segment = tuple[np.ndarray, np.ndarray]  # times (T,) [s], positions (T, n_dims) [m]
#: Mixture size for a fused transition, and the samples per demo it sees on the normalised time grid.
TRANSITION_COMPONENTS = 12
TRANSITION_GRID = 200


def _check(segments: list[Segment], what: str) -> None:
    if len(segments) < 1:
        raise LearningError(f"{what}: no segments to fuse")
    dims = {np.asarray(y).reshape(len(np.asarray(t)), -1).shape[1] for t, y in segments}
    if len(dims) != 1:
        raise LearningError(f"{what}: the demonstrations' segments have different dimensions {sorted(dims)}")


def _phase_shift(reference: np.ndarray, other: np.ndarray) -> int:
    """The circular shift k (grid steps) that best lays ``other`` (M, d) onto ``reference`` (M, d):
    ``other[(i + k) % M] ~ reference[i]`` in least squares (both centred)."""
    corr = np.fft.irfft(np.sum(np.conj(np.fft.rfft(reference, axis=0)) * np.fft.rfft(other, axis=0), axis=1),
                        len(reference))
    return int(np.argmax(corr))


def fuse_periodic(segments: list[Segment], *, n_basis: int = DEFAULT_N_BASIS,
                  n_components: int = DEFAULT_N_COMPONENTS, alpha: float = DEFAULT_ALPHA,
                  n_template: int = DEFAULT_N_TEMPLATE, seed: int = 0) -> tuple[PeriodicMP, dict]:
    """One periodic MP from the same wiping phase in several demonstrations, and its spread (module docstring).

    segments : [(t (T_j,) [s], y (T_j, n_dims) [m])], one per demonstration, in one frame.
    Returns (mp, spread) with spread keys ``path_rms_m``, ``path_max_std_m``, ``freq_std_hz``,
    ``centre_std_m``, ``amplitude_std_m``, ``n_demos``.
    """
    _check(segments, "fusing periodic MPs")
    labelled = [phase_labelled(t, y, n_components) for t, y in segments]
    own = [periodic_template(lab.phase_rad, lab.y, n_template, lab.n_components, seed=seed)[1] for lab in labelled]
    centres = np.array([tpl.mean(axis=0) for tpl in own])
    centre = centres.mean(axis=0)
    shifts = [_phase_shift(own[0] - centres[0], tpl - c) for tpl, c in zip(own, centres)]
    per_demo = max(MAX_GMM_SAMPLES // len(segments), 200)
    phases, ys = [], []
    for lab, k, c in zip(labelled, shifts, centres):
        take = np.linspace(0, len(lab.y) - 1, min(per_demo, len(lab.y))).astype(int)
        phases.append(lab.phase_rad[take] - TWO_PI * k / n_template)
        ys.append(lab.y[take] - c + centre)
    n_comp = max(lab.n_components for lab in labelled)
    grid, fused, _ = periodic_template(np.concatenate(phases), np.vstack(ys), n_template, n_comp, seed=seed)
    first = labelled[0]
    omegas = np.array([lab.omega_rad_s for lab in labelled])
    mp = mp_from_template(grid, fused, n_comp, float(omegas.mean()), alpha, alpha / 4.0, n_basis,
                          first.phase_start_rad, first.phase_end_rad,
                          float(np.mean([lab.n_cycles for lab in labelled])))
    aligned = np.stack([np.roll(tpl - c, -k, axis=0) for tpl, c, k in zip(own, centres, shifts)]) + centre
    std = np.linalg.norm(aligned.std(axis=0), axis=1)  # (M,) spread across demos at each phase
    amplitudes = [0.5 * float((tpl.max(axis=0) - tpl.min(axis=0)).max()) for tpl in own]
    spread = {"n_demos": len(segments),
              "path_rms_m": float(np.sqrt(np.mean(np.sum((aligned - fused) ** 2, axis=2)))),
              "path_max_std_m": float(std.max()),
              "freq_std_hz": float(omegas.std() / TWO_PI),
              "centre_std_m": float(np.linalg.norm(centres.std(axis=0))),
              "amplitude_std_m": float(np.std(amplitudes))}
    return mp, spread


def _gmr_line(s_grid: np.ndarray, s: np.ndarray, y: np.ndarray, n_components: int, seed: int) -> np.ndarray:
    """E[y | s] (len(s_grid), n_dims) of a full-covariance Gaussian mixture over the samples (s (K,), y (K, d))."""
    from sklearn.mixture import GaussianMixture

    data = np.column_stack([s, y])
    scale = data.std(axis=0) + 1e-12
    g = GaussianMixture(n_components, covariance_type="full", reg_covar=1e-6, random_state=seed).fit(data / scale)
    mu, cov = g.means_, g.covariances_
    q = s_grid / scale[0]
    d = q[:, None] - mu[None, :, 0]  # (G, K)
    var = cov[:, 0, 0]
    logw = np.log(g.weights_) - 0.5 * np.log(TWO_PI * var) - 0.5 * d**2 / var
    w = np.exp(logw - logw.max(axis=1, keepdims=True))
    w /= w.sum(axis=1, keepdims=True)
    cond = mu[None, :, 1:] + d[:, :, None] * (cov[:, 1:, 0] / var[:, None])[None]  # (G, K, d)
    return np.einsum("gk,gkd->gd", w, cond) * scale[1:]


def fuse_transitional(segments: list[Segment], *, seed: int = 0, **learn_kwargs) -> tuple[TransitionalMP, dict]:
    """One transitional MP from the same transition in several demonstrations, and its spread (module docstring).

    segments : [(t (T_j,) [s], y (T_j, n_dims) [m])], one per demonstration, in one frame.
    Returns (mp, spread) with spread keys ``path_rms_m``, ``path_max_std_m`` (of the moves from each start),
    ``start_std_m``, ``duration_std_s``, ``n_demos``.
    """
    _check(segments, "fusing transitional MPs")
    grid = np.linspace(0.0, 1.0, TRANSITION_GRID)
    paths, durations = [], []
    for t, y in segments:
        t = np.asarray(t, float)
        y = np.asarray(y, float).reshape(len(t), -1)
        if len(t) < 2 or not np.all(np.diff(t) > 0):
            raise LearningError("fusing transitional MPs: a segment's times must increase strictly")
        durations.append(float(t[-1] - t[0]))
        s = (t - t[0]) / durations[-1]
        paths.append(np.column_stack([np.interp(grid, s, y[:, k]) for k in range(y.shape[1])]))
    paths_a = np.stack(paths)  # (n, G, d)
    starts = paths_a[:, :1, :]
    moves = paths_a - starts
    if len(segments) == 1:
        mean_move = moves[0]
    else:
        n_comp = min(TRANSITION_COMPONENTS, len(segments) * TRANSITION_GRID // 20)
        mean_move = _gmr_line(grid, np.tile(grid, len(segments)), moves.reshape(-1, moves.shape[2]), n_comp, seed)
        mean_move -= mean_move[:1]  # the regression's value at s = 0 is the starts' (zero) up to its ripple
    mean_path = starts.mean(axis=0) + mean_move
    duration = float(np.mean(durations))
    mp = learn_transitional(grid * duration, mean_path, **learn_kwargs)
    std = np.linalg.norm(moves.std(axis=0), axis=1)
    spread = {"n_demos": len(segments),
              "path_rms_m": float(np.sqrt(np.mean(np.sum((moves - mean_move) ** 2, axis=2)))),
              "path_max_std_m": float(std.max()),
              "start_std_m": float(np.linalg.norm(starts[:, 0].std(axis=0))),
              "duration_std_s": float(np.std(durations))}
    return mp, spread
