"""The described arm: the KUKA LBR iiwa 14 with its eraser (``description/``, URDF), its Pinocchio model (kinematics,
dynamics, limits, inverse kinematics) and its joints' rotor inertia and friction. The simulator and the controller load
the same description; the simulated arm may be set to differ from it, the controller's model never does."""

__all__ = ["description", "joint_dynamics", "reach", "robot_model"]
