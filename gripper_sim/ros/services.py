"""The node's simulation services: ``~/reset``, ``~/pause``, ``~/step``, ``~/jaw/open``."""
from __future__ import annotations

from rclpy.callback_groups import CallbackGroup
from std_srvs.srv import SetBool, Trigger

from gripper_sim_interfaces.srv import Step

MAX_STEPS_PER_REQUEST = 1_000_000


class SimServices:
    """Serves the simulation services of ``node`` (a ``SimNode``) in ``group``."""

    def __init__(self, node, group: CallbackGroup):
        self._node = node
        node.create_service(Trigger, '~/reset', self._on_reset, callback_group=group)
        node.create_service(SetBool, '~/pause', self._on_pause, callback_group=group)
        node.create_service(Step, '~/step', self._on_step, callback_group=group)
        node.create_service(Trigger, '~/jaw/open', self._on_open, callback_group=group)

    def _on_reset(self, request, response):
        self._node.reset_simulation('the simulation was reset (~/reset)')
        response.success = True
        response.message = 'simulation reset to t = 0'
        self._node.get_logger().info(response.message)
        return response

    def _on_pause(self, request, response):
        node = self._node
        loop = node.physics
        # Under the lock: once this answers "paused", the physics thread takes no step.
        with node.lock:
            loop.paused = bool(request.data)
            if not loop.paused:
                loop.reanchor()
            sim_time = node.sim.time
        loop.wake()
        response.success = True
        state = 'paused' if loop.paused else 'running'
        response.message = f'{state} at t = {sim_time:.6f} s'
        node.get_logger().info(response.message)
        return response

    def _on_step(self, request, response):
        node = self._node
        if not node.paused:
            response.success = False
            response.message = 'refused: the simulation is running; pause it first (~/pause)'
        elif request.steps < 1 or request.steps > MAX_STEPS_PER_REQUEST:
            response.success = False
            response.message = (f'refused: steps must be in [1, {MAX_STEPS_PER_REQUEST}], '
                                f'got {request.steps}')
        else:
            response.success = True
            response.message = f'advanced {request.steps} steps'
            for done in range(request.steps):
                if node.advance() is None:
                    response.success = False
                    response.message = (f'step {done + 1} of {request.steps} failed; the '
                                        'simulation was reset (see the log)')
                    break
        if not response.success:
            node.get_logger().warning(f'step request {response.message}')
        response.sim_time = float(node.sim.time)
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
            node.commands.put('open command', node.sim.command_open)
            response.success = True
            response.message = 'opening the jaws to the initial gap'
        return response
