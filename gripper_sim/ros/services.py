"""The node's simulation services: ``~/reset``, ``~/pause``, ``~/step``, ``~/jaw/open``.

``set_paused`` and ``take_steps`` are also what the simulation_interfaces services
(``simulation_standard``) call.
"""
from __future__ import annotations

from typing import Callable

from rclpy.callback_groups import CallbackGroup, ReentrantCallbackGroup
from std_srvs.srv import SetBool, Trigger

from gripper_sim_interfaces.srv import Step

from gripper_sim.ros.commands import JAWS

MAX_STEPS_PER_REQUEST = 1_000_000
# ~/step checks this often whether the node is shutting down while it waits.
STEP_WAIT = 0.5   # s


class SimServices:
    """Serves the simulation services of ``node`` (a ``SimNode``) in ``group``; ``~/step``
    in a reentrant group of its own, as it waits for the physics thread to take the
    steps: a second request meanwhile runs at once and is refused (``request_steps``),
    not queued behind the first."""

    def __init__(self, node, group: CallbackGroup):
        self._node = node
        node.create_service(Trigger, '~/reset', self._on_reset, callback_group=group)
        node.create_service(SetBool, '~/pause', self._on_pause, callback_group=group)
        node.create_service(Step, '~/step', self._on_step,
                            callback_group=ReentrantCallbackGroup())
        node.create_service(Trigger, '~/jaw/open', self._on_open, callback_group=group)

    def _on_reset(self, request, response):
        self._node.reset_simulation('the simulation was reset (~/reset)')
        response.success = True
        response.message = 'simulation reset to t = 0'
        self._node.get_logger().info(response.message)
        return response

    def set_paused(self, paused: bool, via: str = '~/pause') -> str:
        """Pause or resume the physics (``via``: the request, for the log and for an
        interrupted ``~/step``); returns the message, e.g. ``paused at t = 0.1 s``."""
        node = self._node
        loop = node.physics
        # Under the lock: once this answers "paused", the physics thread takes no step.
        with node.lock:
            loop.paused = bool(paused)
            loop.interrupt_steps(f"interrupted by {via} ({'true' if loop.paused else 'false'})")
            if not loop.paused:
                loop.reanchor()
            sim_time = node.sim.time
        loop.wake()
        message = f"{'paused' if loop.paused else 'running'} at t = {sim_time:.6f} s"
        node.get_logger().info(message)
        return message

    def take_steps(self, steps: int, progress: Callable[[int, int], None] | None = None,
                   canceled: Callable[[], bool] | None = None,
                   period: float = STEP_WAIT) -> tuple[bool, str]:
        """Hand ``steps`` steps to the (paused) physics thread and wait for them:
        (True, 'advanced n steps') or (False, the reason); a failure is logged.

        Every ``period`` wall s meanwhile: ``progress(taken, steps)``, and the request
        ends (before its next step) once ``canceled()`` is true.
        """
        node = self._node
        ok = False
        if steps < 1 or steps > MAX_STEPS_PER_REQUEST:
            message = f'refused: steps must be in [1, {MAX_STEPS_PER_REQUEST}], got {steps}'
        else:
            queued = node.physics.request_steps(int(steps))
            if isinstance(queued, str):
                message = f'refused: {queued}'
            else:
                while not queued.done.wait(period):
                    if node.physics.stopped:
                        queued.finish('the simulator is shutting down')
                    elif canceled is not None and canceled():
                        with node.lock:
                            node.physics.interrupt_steps('canceled by the client')
                    elif progress is not None:
                        progress(queued.taken, queued.steps)
                ok = queued.stopped_by is None
                message = (f'advanced {queued.taken} steps' if ok else
                           f'stopped after {queued.taken} of {queued.steps} steps: '
                           f'{queued.stopped_by}')
        if not ok:
            node.get_logger().warning(f'step request {message}')
        return ok, message

    def _on_pause(self, request, response):
        response.message = self.set_paused(bool(request.data))
        response.success = True
        return response

    def _on_step(self, request, response):
        """Wait for the steps (own callback group: ``~/pause``, ``~/reset`` and the rest
        answer meanwhile, and stop it)."""
        response.success, response.message = self.take_steps(int(request.steps))
        response.sim_time = float(self._node.sim.time)
        return response

    def _on_open(self, request, response):
        node = self._node
        owner = node.jaws.owner
        if owner is not None:
            response.success = False
            response.message = (f'refused: a {owner.kind} goal is driving the '
                                'jaws (cancel it first)')
            node.get_logger().warning(f'open request {response.message}')
        else:
            node.commands.put('open command', node.sim.command_open, slot=JAWS)
            response.success = True
            response.message = 'opening the jaws to the initial gap'
        return response
