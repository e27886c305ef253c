"""Shared test fixtures and locations."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

REPO = Path(__file__).resolve().parent.parent
#: The real demonstrations live beside the checkout, never inside it.
REAL_DEMOS = REPO.parent / "shared" / "data" / "wiping-demos" / "circular_wiping_dataset.mat"
