"""The robot side in simulation: a PyBullet iiwa with an eraser, a whiteboard with dirt, a camera."""

__all__ = [
    "analytic_camera", "board", "board_sampler", "camera", "cli", "core", "dirt", "drive", "hand", "lbr_stack",
    "params", "plant", "plant_params", "renderer", "robot", "service", "start_view", "step_dynamics", "wiping", "world"
]
