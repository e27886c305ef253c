"""The pad's half turn about its normal: the same pad on the board, A7 turned by pi, nothing else of the arm.

The eraser wipes alike turned half about its normal (a rectangle:
:func:`interfaces.transforms.tool_rotation_on_board` and it turned by pi
about the tool's z), and on the iiwa that half turn is A7 turned by pi and
nothing else: the pad's centre lies on A7's axis and the tool's z along it
(the description's kinematics; ``tests/test_pad_turn.py`` checks it). So
which of the two the controller holds decides A7 to within pi, and where
the other joints leave A7 near a limit the half turn takes it to the middle
of its range.

That happens: on random board 396 the wrist left its singular start
(A6 = 0.01 rad) on the branch where the pad flat over the stain needs A7
at -2.95 rad. There the controller's clearance pushes A6 out of its zone
around zero and A7 out of its zone before the limit, along the same
self-motion the other way: A7 stayed 0.10 rad from its limit, the pad 25 mm
off its reference, 88.7 % of the stain removed. Turned half (A7 + pi:
0.19 rad) the two no longer pull against each other, and the arm settles
with A7 at -0.32 rad, the pad 2.8 mm RMS off its reference, 99.6 %
removed. Which branch the wrist takes on the way depends on how the arm
passes its singular pose, which the controller's torques decide, not a
kinematic plan; so the controller looks where the arm is, over the stain
before it descends (:func:`half_turn_way`), rather than predicting it.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

#: The pad's half turn about its own z: (3, 3), a right multiplication.
HALF_TURN = np.diag([-1.0, -1.0, 1.0])
#: Joints with this much room to every limit [rad] are left as they are: the controller's clearance
#: (``LimitParams.clearance_zone_rad``, 0.5) pushes nothing there.
ENOUGH_ROOM_RAD = 0.5
#: The half turn is made only when it leaves the joints this much more room [rad].
MIN_GAIN_RAD = 0.3


def half_turned(R: np.ndarray) -> np.ndarray:
    """(3, 3) the orientation ``R`` (3, 3) turned by pi about its own z: the same pad on the board."""
    return np.asarray(R, float) @ HALF_TURN


def joint_room_rad(q: np.ndarray, q_min: np.ndarray, q_max: np.ndarray) -> float:
    """The least room [rad] of the joints ``q`` (n,) to their limits ``q_min``, ``q_max`` (n,); negative beyond."""
    return float(np.min(np.minimum(q - q_min, q_max - q)))


def half_turn_way(q: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, enough_rad: float = ENOUGH_ROOM_RAD,
                  gain_rad: float = MIN_GAIN_RAD) -> float:
    """How to turn the pad half for an arm at ``q`` (n,) [rad] (limits ``q_min``, ``q_max`` (n,) [rad], the last
    joint A7): 0.0 not at all (every joint has ``enough_rad`` of room, or the turn gains less than ``gain_rad``),
    +1.0 / -1.0 the way round the pad's z (A7's axis) that takes A7 towards the middle of its range."""
    q = np.asarray(q, float)
    room = joint_room_rad(q, q_min, q_max)
    if room >= enough_rad:
        return 0.0
    way = -1.0 if q[-1] > 0.5 * (q_min[-1] + q_max[-1]) else 1.0
    turned = q.copy()
    turned[-1] += way * math.pi
    return way if joint_room_rad(turned, q_min, q_max) >= room + gain_rad else 0.0


def turn_vector(R0: np.ndarray, R1: np.ndarray, about_z: float = 0.0) -> np.ndarray:
    """(3,) the body rotation vector [rad] taking ``R0`` to ``R1`` (``R1 = R0 exp(theta)``): the shortest one, or
    with ``about_z`` +1 / -1 the one of the two ways round the same axis whose component along the body's z has that
    sign (a half turn goes the way it is asked to, not the way rounding at pi picks)."""
    theta = np.asarray(pin.log3(np.asarray(R0, float).T @ np.asarray(R1, float)), float)
    if about_z == 0.0 or theta[2] * about_z > 0.0:
        return theta
    angle = float(np.linalg.norm(theta))
    if angle < 1e-9:
        return np.array([0.0, 0.0, 2.0 * math.pi * about_z])
    return theta - 2.0 * math.pi * theta / angle  # the same rotation, the other way round
