"""The figures' shared canvas: matplotlib on its headless Agg backend and the atomic PNG writer.

Both figure modules (:mod:`.demo`, :mod:`.primitives`) draw with :data:`plt` from here and save with
:func:`save_figure`, so neither has to import the other for them.
"""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from lampskit.atomic import write_atomic  # noqa: E402

__all__ = ["plt", "save_figure"]


def save_figure(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return write_atomic(path, lambda f: f.write(buf.getvalue()))
