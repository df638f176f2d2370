"""Recording, replay and offline analysis of gripper_sim runs in rosbag2-compatible MCAP.

Nothing here imports rclpy at import time: the writer, reader, recovery and analysis
work from files alone. ``recorder`` imports rclpy when it runs; the replay of a
recording on ROS topics is ``gripper_sim.ros.replay``.
"""
from gripper_sim.recording.errors import RecordingError

__all__ = ['RecordingError']
