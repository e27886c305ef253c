"""The controller process: everything that decides motion, at the robot's rate.

It runs a skill file made by :mod:`lampskit` (it never learns) with the
LAMPS runtime core only: the skill executor (phases, MP chaining, safety
reactions), one control tick (impedance, force regulation, limits in
:mod:`controller.control`), and the Zenoh loops around them.
"""

__all__ = [
    "arm_model", "board_watch", "cli", "command_auth", "control", "core", "core_state", "estop", "executor",
    "executor_stage", "executor_starts", "executor_state", "executor_stops", "executor_types", "free_motion",
    "look_points", "motion", "off_tick", "params", "planner_thread", "rest_posture", "robot_holds", "robot_link",
    "sent_answers", "service", "stain_book", "stains_in", "status_out", "surface_touch", "teach", "tick_io",
    "tool_estimate", "trace"
]
