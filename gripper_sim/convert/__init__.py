"""Pure conversions of simulation results into ROS data structures, without rclpy.

``frames``: the TF tree of the gripper (world -> carriage -> gripper base -> jaws) and
its joint positions; ``urdf``: the gripper's URDF with the same links and joints;
``messages``: a ``StepResult`` as the messages the node publishes (the offline MCAP
writer and the live view build the same); ``finger_markers``: the markers of shaped
fingers and soft pads.
"""
