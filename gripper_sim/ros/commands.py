"""Commands for the simulation: the queue the physics thread drains, and the jaw topics.

Callbacks only validate and enqueue: a command takes effect before the next physics
step (at once while paused), in the physics thread, under the simulation lock.
``JawCommandTopics`` serves ``~/jaw/gap_command``, ``~/jaw/force_command`` and
``~/lift/command`` and answers each on ``~/jaw/command_status``.
"""
from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64, String

from gripper_sim.errors import CommandError, ConfigError
from gripper_sim.workflows.grasp import FORCE_REACHED, stop_reached

#: ``on_done(None)`` once a command ran, ``on_done(reason)`` if the core refused it or
#: a newer command of its slot replaced it (the reason then starts with ``SUPERSEDED``)
DoneCallback = Callable[[str | None], None]
SUPERSEDED = 'superseded by'
#: command slots: a newer command replaces a waiting one of the same slot
JAWS = 'jaws'
LIFT = 'lift'


@dataclass(frozen=True)
class _Command:
    description: str
    command: Callable[[], None]
    on_done: DoneCallback | None
    slot: str | None


def command_problem(value: float, what: str, unit: str, allow_negative: bool = False
                    ) -> str | None:
    """Why a commanded value is unusable, or None (finite, and >= 0 unless allowed)."""
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return f'{what} must be a finite number of {unit}, got {value}'
    if value < 0 and not allow_negative:
        return f'{what} must not be negative, got {value} {unit}'
    return None


class CommandQueue:
    """Commands waiting for the physics thread, run in arrival order.

    A command may name a ``slot`` (e.g. ``'jaws'``, ``'lift'``): only the latest
    set-point of a slot counts, so a newer command for the same slot replaces one that
    is still waiting (its ``on_done`` gets ``SUPERSEDED``-prefixed reason) and takes
    its turn at the end of the queue.

    Args:
        logger: where a command the core refuses is reported.
        wake: called after each ``put`` (wakes a paused or pacing physics thread).
    """

    def __init__(self, logger, wake: Callable[[], None]):
        self._logger = logger
        self._wake = wake
        self._lock = threading.Lock()
        self._pending: deque[_Command] = deque()

    def __len__(self) -> int:
        return len(self._pending)

    def put(self, description: str, command: Callable[[], None],
            on_done: DoneCallback | None = None, slot: str | None = None) -> None:
        """Queue ``command()``; ``description`` names it in the log and in answers."""
        superseded = []
        with self._lock:
            if slot is not None:
                superseded = [c for c in self._pending if c.slot == slot]
                if superseded:
                    self._pending = deque(c for c in self._pending if c.slot != slot)
            self._pending.append(_Command(description, command, on_done, slot))
        for old in superseded:
            if old.on_done is not None:
                old.on_done(f'{SUPERSEDED} {description}')
        self._wake()

    def run_all(self) -> None:
        """Run every queued command (physics thread, under the simulation lock)."""
        while True:
            with self._lock:
                if not self._pending:
                    return
                entry = self._pending.popleft()
            try:
                entry.command()
            except (CommandError, ConfigError) as err:
                self._logger.warning(f'{entry.description} rejected: {err}')
                if entry.on_done is not None:
                    entry.on_done(str(err))
            else:
                if entry.on_done is not None:
                    entry.on_done(None)

    def clear(self) -> None:
        with self._lock:
            self._pending.clear()


class JawCommandTopics:
    """The jaw and lift command topics of ``node`` and their answers.

    One String per command received on ``~/jaw/command_status``: ``accepted:
    <command>`` once applied, ``rejected: <command>: <reason>``, or ``superseded:
    <command>: by <newer command>`` when a newer command for the jaws (gap, force, open)
    or for the lift arrived before the next step applied it: only the latest set-point
    counts (what ``gripper-sim jaw`` waits for). A force command whose jaws then reach
    their stop (``Simulation.smallest_gap``: the deformable fingers' fronts meet, or a
    gap of 0) short of its force gets one more: ``stopped: <command>: the grip is <f>
    N: the jaws are at their stop ...``, logged as a warning too.

    Args:
        node: the ``SimNode`` (its ``sim``, ``jaws`` and ``commands``).
        qos: profile of the command and status topics.
    """

    def __init__(self, node, qos: QoSProfile):
        self._node = node
        self._status = node.create_publisher(String, '~/jaw/command_status', qos)
        group = MutuallyExclusiveCallbackGroup()
        node.create_subscription(Float64, '~/jaw/gap_command', self._on_gap, qos,
                                 callback_group=group)
        node.create_subscription(Float64, '~/jaw/force_command', self._on_force, qos,
                                 callback_group=group)
        node.create_subscription(Float64, '~/lift/command', self._on_lift, qos,
                                 callback_group=group)
        #: (description, N) of the force command applied last whose stop is watched for
        #: (physics thread only), or None
        self._watched: tuple[str, float] | None = None
        node.add_step_listener(self._watch_stop)

    def _command(self, description: str, value: Any, unit: str, slot: str,
                 command: Callable[[float], None], allow_negative: bool = False,
                 watch_stop: bool = False) -> None:
        node = self._node
        problem = command_problem(value, description, unit, allow_negative)
        owner = node.jaws.owner
        if problem is None and owner is not None:
            problem = (f'{description} ignored: a {owner.kind} goal is driving the '
                       'jaws (cancel it first)')
        what = f'{description} {value:g} {unit}'
        if problem is not None:
            node.get_logger().warning(f'rejected: {problem}')
            self._status.publish(String(data=f'rejected: {what}: {problem}'))
            return

        def report(reason: str | None) -> None:
            if reason is None:
                if slot == JAWS:
                    self._watched = (what, float(value)) if watch_stop else None
                text = f'accepted: {what}'
            elif reason.startswith(SUPERSEDED):
                text = f'superseded: {what}: {reason}'
            else:
                text = f'rejected: {what}: {reason}'
            self._status.publish(String(data=text))
        node.commands.put(what, lambda: command(value), report, slot=slot)

    def _on_gap(self, msg: Float64) -> None:
        self._command('gap command', msg.data, 'm', JAWS, self._node.sim.command_gap)

    def _on_force(self, msg: Float64) -> None:
        self._command('force command', msg.data, 'N', JAWS, self._node.sim.command_force,
                      watch_stop=True)

    def _watch_stop(self, result) -> None:
        """After a step (physics thread): report the watched force command once its jaws
        are at their stop short of its force; forget it once they are at the stop, or once
        the jaws are no longer its (a hold, a goal, a reset)."""
        if self._watched is None:
            return
        node, (what, force) = self._node, self._watched
        sim = node.sim
        if sim.gripper_state.mode != 'force' or node.jaws.owner is not None:
            self._watched = None
            return
        if result.gap > sim.smallest_gap:
            return
        self._watched = None
        if result.grip_force >= FORCE_REACHED * force:
            return
        text = (f'stopped: {what}: the grip is {result.grip_force:.3g} N'
                f'{stop_reached(sim, result.gap)}')
        node.get_logger().warning(text)
        self._status.publish(String(data=text))

    def _on_lift(self, msg: Float64) -> None:
        self._command('lift command', msg.data, 'm', LIFT, self._node.sim.command_lift,
                      allow_negative=True)
