"""Segmentation baselines: the paper's K-Means and Affinity Propagation (Fig. 5), and plain scikit-learn OPTICS
cut at a fixed threshold (what our automatic threshold and time-run steps are measured against).

scikit-learn is imported when a baseline runs, so the OPTICS path does not pay for it.
"""

from __future__ import annotations

import warnings

import numpy as np

from lampskit.errors import SegmentationError
from lampskit.learn.optics import ProgressCallback

#: Affinity Propagation runs on at most this many points (it is O(n^2)).
AFFINITY_MAX_POINTS = 800
#: K-Means tries k in this range (inclusive) when not given.
KMEANS_K_RANGE = (2, 8)
#: The fixed-threshold OPTICS baseline's reachability threshold [m] when not given: the automatic threshold of
#: the bundled demo (42 mm), rounded, as a user tuning on one demonstration would fix it.
FIXED_THRESHOLD_M = 0.04


def sklearn_optics_labels(points: np.ndarray, min_samples: int, eps_m: float,
                          progress: ProgressCallback | None) -> np.ndarray:
    """scikit-learn's OPTICS on ``points`` (M, 3) [m], clusters read at the fixed reachability ``eps_m`` [m]
    (``cluster_optics_dbscan``), noise -1: no automatic threshold, no time-run steps."""
    from sklearn.cluster import OPTICS, cluster_optics_dbscan

    o = OPTICS(min_samples=min_samples, max_eps=np.inf).fit(points)
    if progress is not None:
        progress(1, 1)
    return cluster_optics_dbscan(reachability=o.reachability_, core_distances=o.core_distances_,
                                 ordering=o.ordering_, eps=eps_m)


def kmeans_labels(points: np.ndarray, n_clusters: int | None, progress: ProgressCallback | None) -> np.ndarray:
    from sklearn.cluster import KMeans
    from sklearn.metrics import silhouette_score

    if n_clusters is not None:
        if n_clusters > len(points):
            raise SegmentationError(f"n_clusters must be <= the {len(points)} resampled points, got {n_clusters}")
        return KMeans(n_clusters, n_init=4, random_state=0).fit_predict(points)
    lo, hi = KMEANS_K_RANGE
    ks = list(range(lo, min(hi, len(points) - 1) + 1))
    sub = points[:: max(1, len(points) // 2000)]
    best: tuple[float, np.ndarray] | None = None
    for j, k in enumerate(ks):
        km = KMeans(k, n_init=4, random_state=0).fit(points)
        sub_labels = km.predict(sub)
        score = silhouette_score(sub, sub_labels) if len(set(sub_labels.tolist())) > 1 else -1.0
        if best is None or score > best[0]:
            best = (score, km.labels_)
        if progress is not None:
            progress(j + 1, len(ks))
    if best is None:
        raise SegmentationError(f"k-means needs at least {lo + 1} resampled points, got {len(points)}")
    return best[1]


def affinity_labels(points: np.ndarray, progress: ProgressCallback | None) -> np.ndarray:
    from sklearn.cluster import AffinityPropagation
    from sklearn.exceptions import ConvergenceWarning

    sub = points[:: max(1, int(np.ceil(len(points) / AFFINITY_MAX_POINTS)))]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        centres = AffinityPropagation(damping=0.9, max_iter=1000, random_state=0).fit(sub).cluster_centers_
    if len(centres) == 0:
        raise SegmentationError(f"Affinity Propagation found no exemplars in {len(sub)} points (did not converge)")
    if progress is not None:
        progress(1, 1)
    d2 = np.sum((points[:, None, :] - centres[None, :, :]) ** 2, axis=2)
    return np.argmin(d2, axis=1)
