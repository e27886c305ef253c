"""Whether a run's report draws its plots: the environment switch, in a module light enough to import anywhere.

A campaign's process and each of its Ray workers set it per cell; importing
:mod:`launch.report` for the name would load the controller's modules there
(about 2 s of imports, the report's maths share the controller's).
"""

from __future__ import annotations

import os

#: ``0`` in the environment: the report of a run (the recorder's, ``lamps up``'s) draws no plots (``1``, unset: it
#: does); a campaign sets it per cell (``lamps campaign --cell-plots``). ``lamps report`` always draws them.
PLOTS_ENV = "LAMPS_REPORT_PLOTS"


def plots_from_env() -> bool:
    """Whether reports draw their plots, from :data:`PLOTS_ENV` (ValueError naming it for another value)."""
    raw = os.environ.get(PLOTS_ENV, "").strip().lower()
    if raw not in ("", "0", "1", "true", "false", "yes", "no"):
        raise ValueError(f"{PLOTS_ENV} must be 0 or 1, got {raw!r}")
    return raw not in ("0", "false", "no")
