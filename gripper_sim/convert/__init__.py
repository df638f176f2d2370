"""Pure conversions of simulation results into ROS data structures, without rclpy.

``frames``: the TF tree of the gripper (world -> carriage -> gripper base -> jaws) and
its joint positions; ``urdf``: the gripper's URDF with the same links and joints.
"""
