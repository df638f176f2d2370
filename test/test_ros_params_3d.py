"""The node's physics parameters report the configuration it runs: a node started in 3D
declares the 3D defaults (e.g. ``physics.sim.dt`` 20 ms), not the 2D ones."""
from __future__ import annotations

import os

import rclpy
from rclpy.parameter import Parameter

from gripper_sim.configuration import SCHEMA
from gripper_sim.ros.node import SimNode
from gripper_sim.ros.process import free_domain_id, ros_environment
from test_recording_innode import _ENV_KEYS


def test_a_3d_node_declares_the_3d_defaults(monkeypatch):
    domain = free_domain_id(os.getpid())
    env = ros_environment(domain)
    for key in _ENV_KEYS:
        monkeypatch.setenv(key, env[key])
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        node = SimNode(start=False, context=context, parameter_overrides=[
            Parameter('foxglove_port', value=0), Parameter('physics.dimension', value=3)])
        try:
            dt = node.get_parameter('physics.sim.dt').value
            assert dt == SCHEMA['sim.dt'].default_3d != SCHEMA['sim.dt'].default
            assert node.sim.dt == dt == node.params.config['sim.dt']
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
