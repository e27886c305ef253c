"""The controller process: everything that decides motion.

``controller.lamps`` holds the skill-learning maths (segmentation, periodic
and transitional movement primitives, skill files, planner); it has no
network or simulator dependency and is usable offline from the CLI.
"""
