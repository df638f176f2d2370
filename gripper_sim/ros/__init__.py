"""The ROS 2 adapter: the ``gripper_sim`` node, its actions, the example controller, replay.

Everything here imports rclpy, the core does not. The message contents the node
publishes are built without rclpy by ``gripper_sim.convert.messages`` (the offline MCAP
writer uses it too).
"""
