"""One root exception for the Zenoh contract, with one subclass per edge."""

from __future__ import annotations


class InterfaceError(Exception):
    """Root of every error raised deliberately by :mod:`interfaces`."""


class MessageDecodeError(InterfaceError, ValueError):
    """Bytes that are not a valid message of the expected type and version.

    Services catch exactly this, count it, log it and drop the sample.
    """


class ConfigError(InterfaceError, ValueError):
    """A configuration file or override is malformed or out of range."""
