"""Another node of the same name in the ROS graph: refused at start-up, warned about later.

Two simulators of one name in one domain would interleave two timelines on ``/clock``
and the state topics and both execute every goal. A starting node looks for a namesake
until ``NAMESAKE_WAIT`` s after its creation (discovery on loopback takes 0.25-0.5 s,
longer on a loaded machine) and refuses to start if it finds one
(``NameInUseError``; ``gripper-sim node`` exits 2). A namesake that shows up later
(started within the same moment, found late by a slow discovery on a loaded machine, or
its network joined) is a warning, once per appearance, in the log of each node that
sees it. Which of the two came later is settled on a hidden topic, ``~/_instance``:
each node says there when it started (wall clock) with a random token, kept for late
joiners; a node that hears of an earlier namesake marks itself the later one
(``NamesakeWatch.later``) and ``gripper-sim node`` then stops it with exit code 2, as if
it had found the namesake at start-up. The earlier node goes on.
"""
from __future__ import annotations

import secrets
import threading
import time

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from gripper_sim.errors import GripperSimError

NAMESAKE_WAIT = 2.0    # s after the node's creation
CHECK_PERIOD = 1.0     # s between checks while running
POLL = 0.05            # s between looks at start-up
#: where each simulator says when it started: "<wall clock s> <token>"
INSTANCE_TOPIC = '~/_instance'
#: each node's announcement, kept for a namesake that joins later
INSTANCE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: what a node hears: its own announcement and its namesakes', which may all arrive before
#: its executor takes the first (one kept would let a later one displace an earlier one)
HEARD_QOS = QoSProfile(depth=32, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)


class NameInUseError(GripperSimError):
    """Another node with this node's fully qualified name is in the ROS graph."""


def namesakes(node: Node) -> int:
    """How many other nodes in the graph have ``node``'s name and namespace."""
    mine = (node.get_name(), node.get_namespace())
    return sum(1 for entry in node.get_node_names_and_namespaces() if entry == mine) - 1


def _advice(node: Node) -> str:
    return (f'another node named {node.get_fully_qualified_name()} runs in ROS domain '
            f'{node.context.get_domain_id()}: its topics and /clock would interleave with this '
            "one's and both would execute every goal. Stop it, or give this node another "
            'name (--ros-args -r __node:=NAME) or ROS_DOMAIN_ID')


def refuse_namesake(node: Node, created: float, wait: float = NAMESAKE_WAIT) -> None:
    """Look for a namesake until ``created + wait`` (``time.monotonic()`` s).

    Raises:
        NameInUseError: one was found.
    """
    deadline = created + wait
    while True:
        if namesakes(node) > 0:
            raise NameInUseError(_advice(node))
        if time.monotonic() >= deadline:
            return
        time.sleep(min(POLL, max(0.0, deadline - time.monotonic())))


class NamesakeWatch:
    """Warns (once per appearance) when a namesake of ``node`` shows up in the graph, and
    tells whether ``node`` started after a namesake (``later``, see the module docstring).

    Args:
        node: the simulator node.
        started: its start, wall clock s (``time.time()``).
        period: s between looks at the graph.
    """

    def __init__(self, node: Node, started: float, period: float = CHECK_PERIOD):
        self._node = node
        self.seen = False
        self._me = (float(started), secrets.token_hex(8))
        #: set when a namesake that started earlier is heard of; ``reason`` says why
        self.later = threading.Event()
        self.reason = ''
        group = MutuallyExclusiveCallbackGroup()
        node.create_timer(period, self.check, callback_group=group)
        node.create_subscription(String, INSTANCE_TOPIC, self._on_instance, HEARD_QOS,
                                 callback_group=group)
        self._publisher = node.create_publisher(String, INSTANCE_TOPIC, INSTANCE_QOS)
        self._publisher.publish(String(data=f'{self._me[0]!r} {self._me[1]}'))

    def _on_instance(self, msg: String) -> None:
        try:
            stamp, token = msg.data.split()
            other = (float(stamp), token)
        except ValueError:
            self._node.get_logger().warning(
                f'ignored a malformed message on {self._publisher.topic_name}: {msg.data!r}')
            return
        if other[1] != self._me[1] and other < self._me and not self.later.is_set():
            self.reason = _advice(self._node)
            self.later.set()

    def check(self) -> bool:
        """Whether a namesake is in the graph now (logging a change)."""
        found = namesakes(self._node) > 0
        if found and not self.seen:
            self._node.get_logger().warning(_advice(self._node))
        elif self.seen and not found:
            self._node.get_logger().info(
                f'the other node named {self._node.get_fully_qualified_name()} has gone')
        self.seen = found
        return found
