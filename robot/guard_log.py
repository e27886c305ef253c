"""The robot side's account of its limit episodes: each counted and logged with what crossed which limit."""

from __future__ import annotations

import logging
from collections import Counter

from .guard import RobotGuard
from .port import Reading

log = logging.getLogger("robot.server")

#: The counter of each kind of limit episode (:meth:`RobotGuard.observe`'s names).
_EPISODE_COUNTERS = {"joint_speed": "joint_speed_brakes", "tool_speed": "tool_speed_brakes",
                     "press_speed": "press_speed_brakes", "contact_force": "contact_force_yields",
                     "fault": "guard_faults"}


def log_guard_episodes(g: RobotGuard, p, counters: Counter, entered: tuple[str, ...], r: Reading) -> None:
    """Count (``counters``) and log each limit episode of ``g`` that began (``entered``, :meth:`RobotGuard.observe`'s
    names) at reading ``r``, with the thresholds of ``p`` (:class:`~robot.server_params.ServerParams`)."""
    brake, release = p.speed_brake_share * 100, p.speed_release_share * 100
    for what in entered:
        counters[_EPISODE_COUNTERS[what]] += 1
        ahead = g.entry_value.get(what, 0.0)
        if what == "joint_speed":
            j = g.worst_joint
            log.warning("A%d at %.2f rad/s (%.2f by the next cycle), over %.0f %% of its limit: braking until "
                        "every joint is under %.0f %%", j + 1, abs(float(r.dq_rad_s[j])), ahead, brake, release)
        elif what == "tool_speed":
            log.warning("tool at %.2f m/s (%.2f by the next cycle), over %.0f %% of its %.2f m/s limit: braking "
                        "until under %.0f %%", g.tool_speed_m_s, ahead, brake, p.tool_speed_limit_m_s, release)
        elif what == "press_speed":
            log.warning("pad moving into the surface at %.3f m/s (%.3f by the next cycle), over %.0f %% of its "
                        "%.2f m/s limit: %s until under %.0f %%", g.press_speed_m_s, ahead, brake,
                        p.press_speed_limit_m_s, "yielding" if g.touching else "braking", release)
        elif what == "contact_force":
            log.warning("contact force %.1f N (%.1f by the next cycle) over the cap %.0f N: yielding (gravity "
                        "compensated, damped) until under %.0f N", g.force_n, ahead, p.force_cap_n,
                        p.force_cap_n * p.force_release_share)
        else:
            log.error("FAULT-hold: %s; holding whatever is commanded until the operator's e-stop release",
                      g.fault_reason)
