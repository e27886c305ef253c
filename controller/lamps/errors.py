"""One root exception for the skill-learning code, with one subclass per edge.

Every message names the offending value and what would have been valid, so
a command-line user can fix the input without reading the code.
"""


class LampsError(Exception):
    """Root of every error raised deliberately by :mod:`controller.lamps`."""


class DemoError(LampsError, ValueError):
    """A demonstration file or array is unusable (format, values, length)."""


class SegmentationError(LampsError):
    """Segmentation found no usable structure (e.g. no periodic part)."""


class LearningError(LampsError):
    """A movement primitive could not be learned from its segment."""


class SkillFileError(LampsError, ValueError):
    """A skill file is malformed, of an unknown version, or inconsistent."""


class PlanningError(LampsError, ValueError):
    """The planner was given stains or states it cannot plan for."""
