"""The node's simulation services: ``~/reset``, ``~/pause``, ``~/step``, ``~/jaw/open``."""
from __future__ import annotations

from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup
from std_srvs.srv import SetBool, Trigger

from gripper_sim_interfaces.srv import Step

from gripper_sim.ros.commands import JAWS

MAX_STEPS_PER_REQUEST = 1_000_000
# ~/step checks this often whether the node is shutting down while it waits.
STEP_WAIT = 0.5   # s


class SimServices:
    """Serves the simulation services of ``node`` (a ``SimNode``) in ``group``; ``~/step``
    in a group of its own, as it waits for the physics thread to take the steps."""

    def __init__(self, node, group: CallbackGroup):
        self._node = node
        node.create_service(Trigger, '~/reset', self._on_reset, callback_group=group)
        node.create_service(SetBool, '~/pause', self._on_pause, callback_group=group)
        node.create_service(Step, '~/step', self._on_step,
                            callback_group=MutuallyExclusiveCallbackGroup())
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
            loop.interrupt_steps(f"interrupted by ~/pause ({'true' if loop.paused else 'false'})")
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
        """Hand the steps to the physics thread and wait for them (own callback group:
        ``~/pause``, ``~/reset`` and the rest answer meanwhile, and stop it)."""
        node = self._node
        response.success = False
        if request.steps < 1 or request.steps > MAX_STEPS_PER_REQUEST:
            response.message = (f'refused: steps must be in [1, {MAX_STEPS_PER_REQUEST}], '
                                f'got {request.steps}')
        else:
            queued = node.physics.request_steps(int(request.steps))
            if isinstance(queued, str):
                response.message = f'refused: {queued}'
            else:
                while not queued.done.wait(STEP_WAIT):
                    if node.physics.stopped:
                        queued.finish('the simulator is shutting down')
                if queued.stopped_by is None:
                    response.success = True
                    response.message = f'advanced {queued.taken} steps'
                else:
                    response.message = (f'stopped after {queued.taken} of {queued.steps} '
                                        f'steps: {queued.stopped_by}')
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
            node.commands.put('open command', node.sim.command_open, slot=JAWS)
            response.success = True
            response.message = 'opening the jaws to the initial gap'
        return response
