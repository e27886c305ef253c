"""Segmentation of the four real wiping demonstrations (skipped when ../shared/data is absent).

Each holds one periodic part between an approach and a retract, labelled by
hand to a few tens of samples; the labels are read only to score.
"""

from __future__ import annotations

import numpy as np
import pytest

from lampskit.learn.demo import Demonstration
from lampskit.learn.segmentation import segment
from lampskit.learn.segmentation_scores import frame_accuracy, segment_counts

from .conftest import REAL_DEMOS

pytestmark = pytest.mark.realdata


def _load(index: int) -> tuple[Demonstration, np.ndarray]:
    if not REAL_DEMOS.is_file():
        pytest.skip(f"real data absent: {REAL_DEMOS}")
    from scipy.io import loadmat

    m = loadmat(REAL_DEMOS, squeeze_me=True, struct_as_record=False)
    d = m["proc_data"][index]
    x = np.asarray(d.X, dtype=float)
    demo = Demonstration(np.arange(x.shape[1]) * float(d.dt), x[:3].T, source=f"real demo {index}")
    return demo, np.asarray(m["True_states"][index]) == 2


@pytest.mark.parametrize("index", range(4))
def test_real_demo_has_one_periodic_segment(index):
    demo, truth = _load(index)
    seg = segment(demo)
    counts = segment_counts(seg)
    acc = frame_accuracy(seg, truth)
    print(f"real demo {index}: frame accuracy {acc:.3f}, segments {[s.to_dict() for s in seg.segments]}")
    assert counts["periodic"] == 1
    assert acc >= 0.93  # measured 0.947-0.989; the hand labels are only good to tens of samples
