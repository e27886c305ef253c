"""The *release*: the last message for the stack, safe under either damping law of KUKA's joint impedance.

The stack re-applies the last ``LBRTorqueCommand`` for as long as it runs
(lbr_torque_command_controller.cpp:42-55, rolling 218d723). What that last
message does once nobody answers the states:

* a torque overlay (the controller's press) goes on pressing;
* a *hold* (``joint_position`` a fixed pose, zero overlay) leaves the
  stack's PID integrating towards that pose (``c += p (target - measured)``
  every FRI cycle: filters.cpp:56-62, torque_command.cpp:33-37) around the
  robot's joint spring. With the spring ``K``, the PID's rate ``p / T`` and
  the joint's inertia ``m``, the loop is ``m s^3 + D s^2 + (K + D p / T) s +
  K p / T`` when KUKA damps the rate of the commanded position against the
  arm's (``D (dq_cmd - dq)``), stable when ``D (K + D p / T) > m K p / T``
  (it is, for the iiwa's joints at the app's 200 Nm/rad and damping ratio
  0.7), but ``m s^3 + D s^2 + K s + K p / T`` when it damps the arm's rate
  alone (``-D dq``), stable only when ``D > m p / T`` (100 m at p = 0.1 and
  1 ms: at a damping ratio of 0.7 not for A1..A4, whose inertias are 0.9 to
  3.4 kg m^2 at a wiping pose; tests/test_lbr_release.py). KUKA's damping law is
  in no public code; and either way a hold taken while the pad pressed
  brings the pad back to that press.
* the **release**, ``joint_position`` NaN on every joint and zero torque:
  the stack buffers it (system_interface.cpp:347-354, base_command.hpp:32)
  and its FRI side, finding a NaN target, re-initialises its command to the
  measured position with zero torque (torque_command.cpp:20-25,
  base_command.cpp:12-17), every manager cycle again. No overlay, no spring
  deflection, nothing integrated: the robot's joint impedance has nothing to
  push with, under either damping law; the arm rests on the robot's gravity
  compensation (the tool's load data must be right:
  :mod:`robot.lbr.rest_checks`) and a pressed pad backs off.

The adapter ends with the release when it stops; disarmed and running it
sends holds (the measured pose, new every state). If the adapter dies
without a word, the watchdog (:mod:`robot.lbr.watchdog`, run next to the
stack) sends the release.
"""

from __future__ import annotations

import numpy as np

from .msgs import N_JOINTS, encode_torque_command

#: The release's joint position (NaN: the stack re-initialises its command at the measured pose) and torque.
RELEASE_JOINT_POSITION = np.full(N_JOINTS, np.nan)
RELEASE_TORQUE = np.zeros(N_JOINTS)
#: The release as the adapter and the watchdog send it (CDR, little-endian).
RELEASE_BYTES = encode_torque_command(RELEASE_JOINT_POSITION, RELEASE_TORQUE)


def is_release(raw: bytes) -> bool:
    """Whether the CDR bytes ``raw`` are the release."""
    return bytes(raw) == RELEASE_BYTES
