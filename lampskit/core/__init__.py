"""The LAMPS runtime: movement primitives, their runners, skill files, the planner (numpy only).

- :mod:`.periodic`: the periodic DMP, eqs. (1)-(6), and its limit cycle in closed form;
  :mod:`.periodic_runner`: its exact-step 1 kHz runner, built on :mod:`.periodic_step` (the exact step and
  output maps), :mod:`.periodic_forcing` (eq. (4) into preallocated buffers) and :mod:`.periodic_ramp` (the
  effective y_m, r, Omega and stroke and their critically damped filters).
- :mod:`.transitional`: the third-order transitional MP, eqs. (7)-(19);
  :mod:`.transitional_maths`: its equations and tables; :mod:`.transitional_plan`:
  a transition between two states; :mod:`.transitional_runner`: its 1 kHz runner.
- :mod:`.skill`: the skill file; :mod:`.surface`: the demonstration's surface frame;
  :mod:`.rotations`: rotation matrices and quaternions.
- :mod:`.planner`: stain order, MP choice, entry and exit phases, transitions;
  :mod:`.chain`: the learned MPs chained over the stains, one tick at a time, with :mod:`.chain_pass` (its pass
  over the stain it wipes) and :mod:`.chain_jobs` (its jobs on the planner thread);
  :mod:`.rollout`: a plan executed offline at a fixed rate.
"""

__all__ = [
    "chain", "chain_jobs", "chain_pass", "kinematic_bounds", "periodic", "periodic_forcing", "periodic_ramp",
    "periodic_runner", "periodic_step", "planner", "planner_types", "rollout", "rotations", "skill", "stain_order",
    "surface", "transitional", "transitional_maths", "transitional_plan", "transitional_runner"
]
