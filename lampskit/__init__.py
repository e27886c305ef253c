"""lampskit: LAMPS, learning adaptive multi-periodic skills (Liu, Luo, Fang), as a library of its own.

Learn a skill from one demonstration, plan it over new stains, roll it out:
no network, simulator or camera needed. Three layers, each importing only
the ones before it:

- :mod:`lampskit.core`: what runs on the robot. Periodic MPs (eqs. (1)-(6)),
  transitional MPs (eqs. (7)-(19)), their 1 kHz step runners, skill files,
  the planner and the offline rollout. numpy only.
- :mod:`lampskit.learn`: demonstrations in (readers, synthetic demos),
  segmentation (OPTICS, Procedure 1), GMM-GMR, fitting the MPs, the
  baselines, learning a whole skill.
- :mod:`lampskit.figures`: the paper's figures from a demonstration and a skill.

:mod:`lampskit.errors` holds :class:`~lampskit.errors.LampsError`, the one
root of every error the project raises on purpose. The ``lamps demo``,
``learn``, ``segment``, ``plan`` commands are in :mod:`lampskit.cli`.
"""

__all__ = ["atomic", "cli", "core", "errors", "figures", "learn", "spd"]
