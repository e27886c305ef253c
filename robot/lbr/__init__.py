"""The KUKA LBR iiwa as a robot side: a clocked :class:`~robot.port.RobotPort` through lbr_fri_ros2_stack.

:mod:`.adapter` is the port; :mod:`.msgs` the stack's messages on the wire, :mod:`.inbox` their arrival,
:mod:`.readings` the reading made of a state, :mod:`.commands` what goes out; :mod:`.params` the ``[lbr]`` config
table; :mod:`.arming`, :mod:`.guards`, :mod:`.watches`, :mod:`.rest_checks` what is checked before and while it
commands; :mod:`.compensation`, :mod:`.tip`, :mod:`.stack_chain` what it undoes or brings over of the stack;
:mod:`.brake`, :mod:`.release`, :mod:`.watchdog` how it stops; :mod:`.preflight` the checks that move nothing.
"""

__all__ = [
    "adapter", "arming", "brake", "commands", "compensation", "guards", "inbox", "msgs", "params", "preflight",
    "readings", "release", "rest_checks", "stack_chain", "tip", "watchdog", "watches"
]
