"""The node's latched topics: ``/tf_static`` and ``robot_description``, sent once.

The node publishes them once, transient local (keep-last 1, reliable), as tf2's static
broadcaster and robot_state_publisher do (``gripper_sim.ros.description``), so a
subscriber that joins later still gets them. A recording holds them as ``ros2 bag
record`` does a latched topic: one message at the start, the channel's
``offered_qos_profiles`` saying ``durability: transient_local`` (so ``replay``
publishes it latched again). The messages come from the gripper's frames
(``convert.frames.GripperFrames``) alone: the recorders and the live view build the
very messages the node publishes.
"""
from __future__ import annotations

from typing import Any

from std_msgs.msg import String

from gripper_sim.convert.frames import GripperFrames, static_transforms
from gripper_sim.convert.messages import time_msg, transform_message
from gripper_sim.convert.urdf import gripper_urdf
from gripper_sim.recording import qos

#: suffix -> (name as the node creates it, ROS type): '/tf_static' is absolute,
#: 'robot_description' relative to the node's namespace (as robot_state_publisher's)
LATCHED_TOPICS: dict[str, tuple[str, str]] = {
    'tf_static': ('/tf_static', 'tf2_msgs/msg/TFMessage'),
    'robot_description': ('robot_description', 'std_msgs/msg/String'),
}

#: the QoS the node offers them with (keep-last 1, reliable, transient local)
LATCHED_PROFILE = qos.default_profile(durability='transient_local', depth=1)


def latched_topic(suffix: str, namespace: str = '/') -> str:
    """Fully qualified name of latched topic ``suffix`` for a node in ``namespace``.

    >>> latched_topic('robot_description', '/g1')
    '/g1/robot_description'
    """
    name = LATCHED_TOPICS[suffix][0]
    if name.startswith('/'):
        return name
    ns = namespace.strip('/')
    return f'/{ns}/{name}' if ns else f'/{name}'


def latched_messages(frames: GripperFrames) -> dict[str, Any]:
    """``{suffix: message}``: the static transforms (stamp 0) and the URDF of ``frames``."""
    return {
        'tf_static': transform_message(static_transforms(frames), time_msg(0)),
        'robot_description': String(data=gripper_urdf(frames)),
    }
