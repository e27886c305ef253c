"""``ControllerCore.tick`` and ``TeachCore.tick`` for tests holding a state's parts as arrays.

The records filled, the torques returned.

One :class:`~controller.tick_io.TickInput` and :class:`~controller.tick_io.TickOutput` per core, as the service
keeps them; the torques returned are the output record's buffer (copy to keep), as the service reads them.
"""

from __future__ import annotations

import weakref

import numpy as np

from controller.core import ControllerCore
from controller.teach import TeachCore
from controller.tick_io import LastCommand, TickInput, TickOutput

Core = ControllerCore | TeachCore
_RECORDS: weakref.WeakKeyDictionary[Core, tuple[TickInput, TickOutput]] = weakref.WeakKeyDictionary()


def tick(core: Core, q, dq, wrench, gravity_compensated: bool, dt_s: float, tau_max_nm=None,
         applied_nm=None, robot_held: bool = False, running_nm=None) -> np.ndarray:
    """One tick of ``core``: ``applied_nm`` known -> ``APPLIED``, ``robot_held`` -> ``HELD``, else ``UNKNOWN``
    (``running_nm`` what the robot ran on, when known); ``tau_max_nm`` None: the robot declares no limit."""
    if core not in _RECORDS:
        _RECORDS[core] = (TickInput.zeros(core.model.nq), TickOutput.zeros(core.model.nq))
    inp, out = _RECORDS[core]
    inp.set_state(q, dq, wrench, dt_s, gravity_compensated)
    inp.tau_max_nm[:] = np.inf if tau_max_nm is None else tau_max_nm
    last = LastCommand.HELD if robot_held else LastCommand.APPLIED if applied_nm is not None else LastCommand.UNKNOWN
    inp.set_last(last, applied_nm, running_nm)
    core.tick(inp, out)
    return out.tau_nm
