"""The project's one exception root, :class:`LampsError`, and the LAMPS library's subclasses.

Every error the project raises on purpose derives from :class:`LampsError`,
so a caller (a CLI, a service loop, a test) catches one type; each concern
has its own subclass: here the library's (demonstrations, segmentation,
learning, skill files, planning), in :mod:`interfaces.errors` the contract's
(messages, configuration), and one per process package where it needs one.
Every message names the offending value and what would have been valid, so
a command-line user can fix the input without reading the code.
"""


class LampsError(Exception):
    """Root of every error raised deliberately anywhere in the project."""


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
