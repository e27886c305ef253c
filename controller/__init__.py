"""The controller process: everything that decides motion, at the robot's rate.

It runs a skill file made by :mod:`lampskit` (it never learns) with the
LAMPS runtime core only: the skill executor (phases, MP chaining, safety
reactions), one control tick (impedance, force regulation, limits in
:mod:`controller.control`), and the Zenoh loops around them.
"""
