"""The contact band of a wiped surface: how far from its plane a pad still touches it (steps 5b and 6)."""

from __future__ import annotations

import numpy as np

#: The contact band: this many times the :data:`BAND_QUANTILE` of the run's distances from their plane [-]
#: (the lower quartile: a hop's samples, up to three in four, leave it alone) ...
BAND_FACTOR = 8.0
BAND_QUANTILE = 0.25
#: ... at least this [m] (a foam pad's give; sensor noise on a flat stroke) ...
BAND_MIN_M = 0.005
#: ... plus this margin [m]: a lift is higher than the band by more than this.
LIFT_MARGIN_M = 0.005
#: A lift lasts at least this [s] (a hop of 1 s with a 2 cm lift stays above 1 cm for about 0.7 s).
LIFT_MIN_S = 0.3


def contact_band(h: np.ndarray) -> float:
    """The contact band [m] of heights ``h`` (K,) [m]: :data:`BAND_FACTOR` times their :data:`BAND_QUANTILE`
    of ``|h|``, at least :data:`BAND_MIN_M`."""
    return max(BAND_MIN_M, BAND_FACTOR * float(np.quantile(np.abs(h), BAND_QUANTILE)))
