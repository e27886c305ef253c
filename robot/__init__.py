"""The robot side of the cell: one port, one protocol, several robots.

:mod:`robot.port` is what a robot side implements (read / write / hold,
lifecycle, capabilities); :mod:`robot.server` owns the ``robot/*``
protocol for all of them; :mod:`robot.gate` checks every command before it
reaches hardware and makes it a :mod:`robot.command` (torques or a hold);
:mod:`robot.late_answer` damps what a late answer has not seen.
Implementations: the simulator (:mod:`sim.service`), a mock arm for tests
(:mod:`robot.mock`) and the KUKA LBR iiwa through lbr_fri_ros2_stack
(:mod:`robot.lbr`).
"""

__all__ = [
    "cli", "command", "command_auth", "estop", "gate", "guard", "guard_bands", "guard_log", "guard_model",
    "late_answer", "lbr", "mock", "port", "served_controller", "server", "server_cycle", "server_params",
    "server_status"
]
