"""The robot side: PyBullet whiteboard simulator (arrives with issue 3)."""
