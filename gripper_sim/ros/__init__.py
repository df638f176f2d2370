"""The ROS 2 adapter: the ``gripper_sim`` node, its actions, the example controller.

Only ``gripper_sim.ros.messages`` is meant for use without a running node (the
offline MCAP writer calls it); everything here imports rclpy, the core does not.
"""
