"""The wire contract every process shares: keys, messages and their checks and codec, the access list's roles, the
commands' authentication, frames and transforms. Its runtime (sessions, settings, security) is :mod:`runtime`, the
arm's model :mod:`arm`."""

__all__ = [
    "access", "arm_auth", "arm_estimate", "board_markers", "codec", "errors", "keys", "message_checks",
    "message_limits", "messages", "stain_shape", "transforms"
]
