"""The contract's errors: one subclass of the project root :class:`~lampskit.errors.LampsError` per edge."""

from __future__ import annotations

from lampskit.errors import LampsError


class InterfaceError(LampsError):
    """Root of every error raised deliberately by :mod:`interfaces` (messages, configuration, robot model)."""


class MessageDecodeError(InterfaceError, ValueError):
    """Bytes that are not a valid message of the expected type and version.

    Services catch exactly this, count it, log it and drop the sample.
    """


class ConfigError(InterfaceError, ValueError):
    """A configuration file or override is malformed or out of range."""
