"""Every feedback message of one's own action goals, also what is still unread when the
result comes.

rclpy's ``ActionClient`` forgets a goal's feedback callback as soon as it takes the
goal's result (``rclpy/action/client.py``), so feedback that a busy client has not read
by then is dropped: a short final phase can vanish from a client's view. ``GoalFeedback``
subscribes to the action's feedback topic itself and hands each message to the handler
of its goal id; send the goal with ``goal_uuid=feedback.new_goal(handler)``.
"""
from __future__ import annotations

import time
import uuid
from typing import Any, Callable

from rclpy.node import Node
from rclpy.qos import QoSProfile
from unique_identifier_msgs.msg import UUID


class GoalFeedback:
    """The feedback topic of the action ``action_name`` (of type ``action_type``), read by
    ``node``, dispatched by goal id. ``received`` counts the messages handed out."""

    def __init__(self, node: Node, action_type: Any, action_name: str, qos: QoSProfile):
        self._handlers: dict[bytes, Callable[[Any], None]] = {}
        self.received = 0
        self.subscription = node.create_subscription(
            action_type.Impl.FeedbackMessage, f'{action_name}/_action/feedback',
            self._on_message, qos)

    def new_goal(self, handler: Callable[[Any], None]) -> UUID:
        """A fresh goal id whose feedback (the action's ``Feedback`` message) goes to
        ``handler``; pass it to ``send_goal_async(..., goal_uuid=...)``."""
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        self._handlers[bytes(goal_id.uuid)] = handler
        return goal_id

    def _on_message(self, message) -> None:
        handler = self._handlers.get(bytes(message.goal_id.uuid))
        if handler is not None:
            self.received += 1
            handler(message.feedback)

    def drain(self, spin_once: Callable[[float], None], quiet: float = 0.2) -> None:
        """Read the feedback still queued (call it once the result has come): spins with
        ``spin_once(timeout_s)`` until no feedback has come for ``quiet`` s."""
        quiet_until = time.monotonic() + quiet
        while time.monotonic() < quiet_until:
            received = self.received
            spin_once(0.05)
            if self.received != received:
                quiet_until = time.monotonic() + quiet
