"""The robot side in simulation: a PyBullet iiwa with an eraser, a whiteboard with dirt, a camera."""
