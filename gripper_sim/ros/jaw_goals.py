"""What the two action servers share about their goals: tickets, cancel, feedback QoS.

Every accepted goal gets a ticket (``JawOwnership.ticket``) in its goal callback, before
the client hears it was accepted, so tickets follow the order in which clients' goals
were accepted; however the executor orders their execute callbacks, the newest goal is
the one that drives the jaws. A cancel request marks the run before rclpy does
(``ActiveGoal.cancel``), so the run sees it as soon as it wakes.
"""
from __future__ import annotations

from rclpy.action import CancelResponse, GoalResponse
from rclpy.qos import QoSProfile, ReliabilityPolicy

from gripper_sim.ros.sync import ActiveGoal, JawOwnership

FEEDBACK_PERIOD = 0.05     # s, sim time and wall time
# Feedback history kept for a slow client: every phase change reaches it even when it
# reads late (the default depth 10 is 0.2 s of feedback at 50 messages per s).
FEEDBACK_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)


class JawGoals:
    """The goals of one action server: their tickets and the runs executing.

    Args:
        jaws: the node's jaw ownership (hands out the tickets).
    """

    def __init__(self, jaws: JawOwnership):
        self._jaws = jaws
        self._tickets: dict[int, int] = {}   # id(goal request) -> ticket
        self._runs: dict[int, ActiveGoal] = {}

    def accept(self, goal) -> GoalResponse:
        """Accept ``goal`` (a valid goal request, in the goal callback) with a ticket."""
        self._tickets[id(goal)] = self._jaws.ticket()
        return GoalResponse.ACCEPT

    def ticket(self, goal_handle) -> int:
        """The ticket of an accepted goal (once, at the start of its execution; the
        handle's ``request`` is the goal request the goal callback saw)."""
        return self._tickets.pop(id(goal_handle.request))

    def cancel(self, goal_handle) -> CancelResponse:
        """The server's ``cancel_callback``: always accepted."""
        for run in list(self._runs.values()):
            if run.goal_handle is goal_handle:
                run.cancel()
        return CancelResponse.ACCEPT

    def add(self, run: ActiveGoal) -> None:
        self._runs[id(run)] = run

    def remove(self, run: ActiveGoal) -> None:
        self._runs.pop(id(run), None)
