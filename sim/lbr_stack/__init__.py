"""lbr_fri_ros2_stack simulated: the KUKA iiwa behind the stack's messages, behaving as the stack's code does.

:mod:`.params` the ``[lbr_peer]`` table (the stack's configuration, the
robot-side application's, the session's); :mod:`.stack` the stack's and the
robot's behaviours as pure state machines and filters; :mod:`.peer` the
process that runs them on the PyBullet arm and speaks the bridge's keys,
with :mod:`.commands` its torque-command subscription; :mod:`.cli`
``lamps lbr-peer``. ``docs/real-robot.md`` lists each behaviour
with the stack's file, line and commit.
"""

__all__ = ["broadcast", "cli", "commands", "fri_robot", "params", "peer", "stack"]
