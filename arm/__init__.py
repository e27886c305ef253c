"""The described arm: the KUKA LBR iiwa 14 with its eraser (``description/``, URDF), its Pinocchio model (kinematics,
dynamics, limits, inverse kinematics), its joints' rotor inertia and friction, its reach in closed form (where the
elbow, the shoulder and the wrist leave the pad; the test the controller skips stains by and the random boards pass),
its silhouette (which board points it hides from a camera), its rest posture planned out of the controller's
clearance zones, the pad's half turn about its normal (A7 by pi: the same pad on the board) and the branch a
start pose puts the arm on (which of its configurations keeps the joints off their limits over a whole board). The
simulator and the controller load the same description; the simulated arm may be set to differ from it, the
controller's model never does."""

__all__ = ["branch", "description", "joint_dynamics", "pad_turn", "posture", "reach", "robot_model", "silhouette"]
