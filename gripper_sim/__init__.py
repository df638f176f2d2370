"""gripper_sim: a parallel-jaw gripper grasping a deformable fruit, simulated."""

__version__ = '0.1.0'
