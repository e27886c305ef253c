"""The contract every process shares: keys, messages, config, the CLI."""

__all__ = [
    "access", "arm_auth", "arm_estimate", "board_markers", "certificates", "cli", "codec", "config", "credentials",
    "description", "errors", "joint_dynamics", "keys", "local_bus", "loop_hygiene", "loop_stats", "message_checks",
    "message_limits", "messages", "priority", "realtime", "robot_model", "service_main", "service_security",
    "session", "stain_shape", "stop_signals", "transforms"
]
