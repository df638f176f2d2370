"""The node's fixed description: ``/tf_static`` and the URDF on ``robot_description``.

Both go out once, transient local (keep-last 1, reliable), as tf2's static broadcaster
and robot_state_publisher publish them: a subscriber that joins later still gets them.
The messages are ``recording.latched``'s, the very ones the recordings and the live view
hold. The moving edges of the same tree go out on ``/tf`` with every state batch
(``messages.build_messages``).
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from gripper_sim.convert.frames import GripperFrames
from gripper_sim.recording.latched import LATCHED_TOPICS, latched_messages

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC_TF_TOPIC = LATCHED_TOPICS['tf_static'][0]
DESCRIPTION_TOPIC = LATCHED_TOPICS['robot_description'][0]   # in the node's namespace


class RobotDescription:
    """Publishes the static frames and the URDF of ``frames`` for ``node``, once.

    Attributes:
        urdf: the URDF text published.
    """

    def __init__(self, node, frames: GripperFrames):
        messages = latched_messages(frames)
        self.urdf = messages['robot_description'].data
        self._static = node.create_publisher(TFMessage, STATIC_TF_TOPIC, LATCHED)
        self._description = node.create_publisher(String, DESCRIPTION_TOPIC, LATCHED)
        self._static.publish(messages['tf_static'])
        self._description.publish(messages['robot_description'])
