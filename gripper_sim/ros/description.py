"""The node's fixed description: ``/tf_static`` and the URDF on ``robot_description``.

Both go out once, transient local (keep-last 1, reliable), as tf2's static broadcaster
and robot_state_publisher publish them: a subscriber that joins later still gets them.
The moving edges of the same tree go out on ``/tf`` with every state batch
(``messages.build_messages``).
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from gripper_sim.convert.frames import GripperFrames, static_transforms
from gripper_sim.convert.messages import time_msg, transform_message
from gripper_sim.convert.urdf import gripper_urdf

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC_TF_TOPIC = '/tf_static'
DESCRIPTION_TOPIC = 'robot_description'   # in the node's namespace


class RobotDescription:
    """Publishes the static frames and the URDF of ``frames`` for ``node``, once.

    Attributes:
        urdf: the URDF text published.
    """

    def __init__(self, node, frames: GripperFrames):
        self.urdf = gripper_urdf(frames)
        self._static = node.create_publisher(TFMessage, STATIC_TF_TOPIC, LATCHED)
        self._description = node.create_publisher(String, DESCRIPTION_TOPIC, LATCHED)
        self._static.publish(transform_message(static_transforms(frames), time_msg(0)))
        self._description.publish(String(data=self.urdf))
