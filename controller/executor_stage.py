"""The skill executor's shared vocabulary (:mod:`controller.executor` and its parts :mod:`controller.board_watch`,
:mod:`controller.executor_stops`): the phases in which it moves or is halted, the stages of its motion and the pad's
lifted and released thresholds."""

from __future__ import annotations

from enum import IntEnum

from interfaces.messages import Phase

#: The phases in which the skill moves the pad towards or over the stains.
ACTIVE = (Phase.APPROACH, Phase.WIPE, Phase.TRANSITION)
#: The phases that hold until a release (:meth:`SkillExecutor.clear`) or a restart.
HALTED = (Phase.FAULT, Phase.ESTOP)
#: The pad counts as off the board this far above it [m] (see :attr:`SkillExecutor.pad_down`).
LIFTED_M = 0.005
#: Below this measured contact force [N] the pad counts as released (:attr:`SkillExecutor.pad_down`).
RELEASED_N = 0.5


class Stage(IntEnum):
    """The motion running inside a phase; :meth:`SkillExecutor.step` calls one handler per stage."""

    FLY = 0  #: to the hover point (quintic in x, y, h) while the pad turns flat
    DESCEND = 1  #: down to the creep height (air mode: to the air height)
    CREEP = 2  #: slowly on towards and past the surface until contact
    PRESS = 3  #: force ramp up to its target, at rest
    CHAIN = 4  #: the learned MPs over the stains (:class:`~lampskit.core.chain.MpChain`)
    UNPRESS = 5  #: in contact: in-plane motion to rest while the force ramps out
    BRAKE = 6  #: in the air: x, y and h to rest together
    LIFT = 7  #: up to the standoff height
    HOLD = 8  #: at rest
    LOOK = 9  #: at the standoff height off the stains awaiting kappa
    SURVEY = 10  #: before the first approach: to the look point of the whole board, then wait for the stains
