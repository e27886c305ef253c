"""How a segmentation compares with hand labels: frame accuracy and segment counts."""

from __future__ import annotations

import numpy as np

from lampskit.errors import SegmentationError
from lampskit.learn.segmentation import Segmentation


def frame_accuracy(segmentation: Segmentation, true_periodic: np.ndarray) -> float:
    """Fraction of samples whose kind (periodic or not) matches the truth.

    Parameters
    ----------
    segmentation : Segmentation
    true_periodic : array of bool, shape (T,)
        True on samples labelled periodic; read here only, never to segment.
    """
    truth = np.asarray(true_periodic)
    if truth.shape != (segmentation.n_samples,):
        raise SegmentationError(f"true_periodic must have shape ({segmentation.n_samples},), got {truth.shape}")
    return float(np.mean(segmentation.periodic_mask == truth.astype(bool)))


def segment_counts(segmentation: Segmentation) -> dict[str, int]:
    """Numbers of ``periodic`` and ``transitional`` segments and of distinct periodic ``clusters``."""
    per = segmentation.periodic_segments
    return {
        "periodic": len(per),
        "transitional": len(segmentation.segments) - len(per),
        "clusters": len({s.cluster for s in per}),
    }


def true_segment_count(true_periodic: np.ndarray) -> int:
    """Number of periodic runs in a label array of shape (T,) (True = periodic)."""
    truth = np.asarray(true_periodic, dtype=bool).astype(int)
    return int(np.sum(np.diff(np.r_[0, truth]) == 1))
