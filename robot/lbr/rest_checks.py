"""What the external torque says with the arm at rest: a pad pressing (a preload) and the tool's load data.

The robot reports the external torque as the measured joint torque less its
own model of the arm and of the load data set on the smartPAD (the stack
copies it: state.cpp:18, rolling 218d723; FRI SDK friLBRState.h
``getExternalTorque``). At rest, in the air, with the tool's load data
right, it is near zero. Two things make it not:

* **A preload.** After the adapter restarts, the stack may go on applying an
  old message: a hold whose target lies in the board, towards which its PID
  integrates (filters.cpp:56-62, torque_command.cpp:33-37), so the robot's
  joint spring presses the pad. An FRI 2 state has no commanded position
  (lbr_fri_idl ``fri-2`` LBRState.msg), so the adapter cannot see the spring's
  deflection, starts its copy of the stack's command at the measured pose,
  and arming would step the torque by the spring times that deflection. The
  board's reaction is in the external torque: :func:`preload_refusal` refuses
  to arm above ``[lbr] arm_preload_max_n`` and says what to do.
* **The tool's load data.** A tool whose mass the robot's load data leaves
  out weighs on the external torque as a vertical force at the tool:
  :func:`load_note` names the tool mass the external torque implies when it
  disagrees with ``[lbr] tool_mass_kg`` by more than ``tool_mass_tolerance_kg``.

Pure functions (numpy, SI units, world axes); the adapter calls them at
arming, the preflight (:mod:`robot.lbr.preflight`) on a state at rest.
"""

from __future__ import annotations

import numpy as np

from arm.robot_model import RobotModel

#: Standard gravity [m/s^2].
GRAVITY_M_S2 = 9.81
#: Damping of the pseudo-inverse that turns external joint torques into a tool wrench.
WRENCH_DAMPING = 0.01


def pad_wrench(model: RobotModel, q: np.ndarray, tau_ext: np.ndarray) -> np.ndarray:
    """(6,) force [N] and torque about the pad centre [Nm], world axes, that explains the external joint torques
    ``tau_ext`` (7,) [Nm] at joint positions ``q`` (7,): ``(J J^T + l^2 I)^-1 J tau_ext``, J the pad's (6, 7)."""
    J = model.tcp_jacobian(q)
    return np.linalg.solve(J @ J.T + WRENCH_DAMPING**2 * np.eye(6), J @ tau_ext)


def implied_tool_mass_kg(wrench: np.ndarray, tool_mass_kg: float) -> float:
    """The tool mass [kg] the external force implies: the load data's ``tool_mass_kg`` plus what weighs on the
    external torque (a force down, world z up, is mass the load data leaves out)."""
    return tool_mass_kg - float(wrench[2]) / GRAVITY_M_S2


def preload_refusal(wrench: np.ndarray, max_n: float, tool_mass_kg: float) -> str | None:
    """Why not to arm with the arm at rest and this pad ``wrench`` (6,) [N, Nm] (world axes), or None: a force
    over ``max_n`` [N] says the pad presses on something (or the load data is far off: the tool mass it implies
    is named too)."""
    f = np.asarray(wrench[:3], float)
    n = float(np.linalg.norm(f))
    if n <= max_n:
        return None
    return (f"the pad presses {n:.1f} N at rest (force [{f[0]:+.1f}, {f[1]:+.1f}, {f[2]:+.1f}] N): restart the "
            "LBRServer app and relaunch the stack (its command starts at the measured pose) or move the arm off; "
            "the stack holds a command away from the arm (an old hold in the board?), arming would step its spring; "
            f"if the pad touches nothing, the load data is off (implies a tool of "
            f"{implied_tool_mass_kg(wrench, tool_mass_kg):.2f} kg; [lbr] arm_preload_max_n = {max_n:g})")


def load_note(wrench: np.ndarray, tool_mass_kg: float, tolerance_kg: float) -> str | None:
    """A note when the tool mass the external force at rest implies is more than ``tolerance_kg`` off the
    configured ``tool_mass_kg`` (the load data set on the smartPAD), or None."""
    implied = implied_tool_mass_kg(wrench, tool_mass_kg)
    if abs(implied - tool_mass_kg) <= tolerance_kg:
        return None
    return (f"the external torque at rest implies a tool of {implied:.2f} kg, [lbr] tool_mass_kg says "
            f"{tool_mass_kg:.2f} kg: set the tool's load data on the smartPAD (mass, centre of mass) to the tool "
            "the arm carries, and tool_mass_kg to it; meanwhile the difference biases the force by "
            f"{abs(implied - tool_mass_kg) * GRAVITY_M_S2:.1f} N")


def spring_preload_nm(q_rad: np.ndarray, q_commanded_rad: np.ndarray | None, stiffness: np.ndarray) -> float | None:
    """The largest joint spring torque [Nm] ``K |q_cmd - q|`` the robot applies (FRI 1: the state carries the
    commanded position), or None (FRI 2: not in the state)."""
    if q_commanded_rad is None:
        return None
    return float(np.max(np.abs(np.asarray(stiffness) * (np.asarray(q_commanded_rad) - np.asarray(q_rad)))))
