"""LAMPS: Learning Adaptive Multi-Periodic Skills (Liu, Luo, Fang).

Pure maths on numpy arrays, one concept per module:

- :mod:`~controller.lamps.demo` / :mod:`~controller.lamps.demo_io`: demonstrations in,
- :mod:`~controller.lamps.synth`: synthetic wiping demonstrations with true labels,
- :mod:`~controller.lamps.optics`, :mod:`~controller.lamps.segmentation`: Procedure 1,
- :mod:`~controller.lamps.periodic`: periodic DMPs, eqs. (1)-(6),
- :mod:`~controller.lamps.transitional`: third-order transitional DMPs, eqs. (7)-(19),
- :mod:`~controller.lamps.skill`, :mod:`~controller.lamps.planner`: skill files and run-time chaining.
"""
