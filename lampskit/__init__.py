"""LAMPS: Learning Adaptive Multi-Periodic Skills (Liu, Luo, Fang).

Pure maths on numpy arrays, one concept per module:

- :mod:`~lampskit.learn.demo` / :mod:`~lampskit.learn.demo_io`: demonstrations in,
- :mod:`~lampskit.learn.synth`: synthetic wiping demonstrations with true labels,
- :mod:`~lampskit.learn.optics`, :mod:`~lampskit.learn.segmentation`: Procedure 1,
- :mod:`~lampskit.core.periodic`: periodic DMPs, eqs. (1)-(6),
- :mod:`~lampskit.core.transitional`: third-order transitional DMPs, eqs. (7)-(19),
- :mod:`~lampskit.core.skill`, :mod:`~lampskit.core.planner`: skill files and run-time chaining.
"""
