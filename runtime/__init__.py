"""The cell's processes at run time, on top of the wire contract (:mod:`interfaces`): settings, Zenoh sessions, mutual
TLS and credentials, stop signals, CPU priorities and real-time set-up, the 1 kHz loops' hygiene and timing, every
service's ``main()`` skeleton and the ``lamps`` command."""

__all__ = [
    "certificates", "cli", "config", "credentials", "local_bus", "loop_hygiene", "loop_stats", "ports", "priority",
    "realtime", "service_main", "service_security", "session", "stop_signals"
]
