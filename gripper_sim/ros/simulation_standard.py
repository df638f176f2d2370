"""The simulation_interfaces services (the standard simulator control of Gazebo, Isaac
Sim and O3DE), as thin layers over the node's own ``~/reset``, ``~/pause`` and ``~/step``
(``services.SimServices``). Named in the node's namespace, as the standard's tools look
for them: ``get_simulator_features``, ``reset_simulation``, ``step_simulation``,
``get_simulation_state``, ``set_simulation_state``, and the ``simulate_steps`` action
(feedback every ``FEEDBACK_PERIOD`` wall s, cancel ends it before the next step).
The entity services are in ``entities``.

Simulation states: PLAYING (running), PAUSED, and STOPPED (set_simulation_state
STOPPED: reset to t = 0 and paused, until it is played, paused or stepped).

Reset scopes: time and state go together; a scope with ``SCOPE_SPAWNED`` (``SCOPE_ALL``,
``SCOPE_DEFAULT``) also brings back the start-up fruit if a spawn replaced it, as the
standard's "dynamically spawned objects are de-spawned" (``~/reset`` keeps it).
"""
from __future__ import annotations

from rclpy.action import ActionServer, CancelResponse
from rclpy.callback_groups import CallbackGroup, ReentrantCallbackGroup
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import Result, SimulationState, SimulatorFeatures
from simulation_interfaces.srv import (GetSimulationState, GetSimulatorFeatures,
                                       ResetSimulation, SetSimulationState, StepSimulation)

#: exactly what the services below implement
FEATURES = (SimulatorFeatures.SIMULATION_RESET, SimulatorFeatures.SIMULATION_STATE_GETTING,
            SimulatorFeatures.SIMULATION_STATE_SETTING,
            SimulatorFeatures.SIMULATION_STATE_PAUSE,
            SimulatorFeatures.STEP_SIMULATION_SINGLE,
            SimulatorFeatures.STEP_SIMULATION_MULTIPLE,
            SimulatorFeatures.STEP_SIMULATION_ACTION,
            SimulatorFeatures.ENTITY_STATE_GETTING, SimulatorFeatures.ENTITY_CATEGORIES,
            SimulatorFeatures.SPAWNABLES, SimulatorFeatures.SPAWNING)
#: spawn_entity takes a fruit preset name or a preset file of this format
SPAWN_FORMATS = ('yaml',)
FEEDBACK_PERIOD = 0.05   # wall s, SimulateSteps progress
_TIME_AND_STATE = ResetSimulation.Request.SCOPE_TIME | ResetSimulation.Request.SCOPE_STATE
#: reset scopes that also de-spawn: the start-up fruit replaces a spawned one
DESPAWNING_SCOPES = (ResetSimulation.Request.SCOPE_DEFAULT, ResetSimulation.Request.SCOPE_ALL,
                     _TIME_AND_STATE | ResetSimulation.Request.SCOPE_SPAWNED)
#: reset scopes our reset covers: time and state together, with or without de-spawning
RESET_SCOPES = DESPAWNING_SCOPES + (_TIME_AND_STATE,)
STATE_NAMES = {SimulationState.STATE_STOPPED: 'STOPPED', SimulationState.STATE_PLAYING:
               'PLAYING', SimulationState.STATE_PAUSED: 'PAUSED',
               SimulationState.STATE_QUITTING: 'QUITTING',
               SimulationState.STATE_NO_WORLD: 'NO_WORLD',
               SimulationState.STATE_LOADING_WORLD: 'LOADING_WORLD'}


def outcome(code: int = Result.RESULT_OK, message: str = '') -> Result:
    """A simulation_interfaces ``Result`` (OK unless ``code`` says otherwise)."""
    return Result(result=code, error_message=message)


class SimulationStandard:
    """Serves the simulation_interfaces services of ``node`` (a ``SimNode``) in
    ``group``; ``step_simulation`` in a reentrant group of its own (it waits for the
    steps; a second request meanwhile is refused at once, not queued)."""

    def __init__(self, node, group: CallbackGroup):
        self._node = node
        self._stopped = False
        node.create_service(GetSimulatorFeatures, 'get_simulator_features',
                            self._on_features, callback_group=group)
        node.create_service(ResetSimulation, 'reset_simulation', self._on_reset,
                            callback_group=group)
        node.create_service(StepSimulation, 'step_simulation', self._on_step,
                            callback_group=ReentrantCallbackGroup())
        node.create_service(GetSimulationState, 'get_simulation_state', self._on_get_state,
                            callback_group=group)
        node.create_service(SetSimulationState, 'set_simulation_state', self._on_set_state,
                            callback_group=group)
        self._simulate = ActionServer(
            node, SimulateSteps, 'simulate_steps', execute_callback=self._on_simulate,
            cancel_callback=lambda goal_handle: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup())

    @property
    def state(self) -> int:
        """The ``SimulationState`` code the node is in."""
        if not self._node.paused:
            self._stopped = False
            return SimulationState.STATE_PLAYING
        return SimulationState.STATE_STOPPED if self._stopped else SimulationState.STATE_PAUSED

    def _on_features(self, request, response):
        response.features = SimulatorFeatures(
            features=list(FEATURES), spawn_formats=list(SPAWN_FORMATS),
            custom_info='gripper_sim: a parallel-jaw gripper and one deformable fruit; '
                        'a reset restores t = 0 and the initial commands (time and state '
                        'together; with SCOPE_SPAWNED also the start-up fruit); '
                        'spawn_entity replaces the fruit (a preset name, file or file:// '
                        'URI), nothing is deleted')
        return response

    def _on_reset(self, request, response):
        if request.scope not in RESET_SCOPES:
            response.result = outcome(
                Result.RESULT_FEATURE_UNSUPPORTED,
                f'reset scope {request.scope} is not supported: time and state are reset '
                'together (SCOPE_TIME | SCOPE_STATE, with SCOPE_SPAWNED also the start-up '
                'fruit; SCOPE_DEFAULT and SCOPE_ALL are all three)')
            return response
        if request.scope in DESPAWNING_SCOPES:
            restored = self._node.entities.restore_startup_fruit()
            if restored is not None:   # the replacement reset the simulation
                response.result = restored
                return response
        self._node.reset_simulation('the simulation was reset (reset_simulation)')
        response.result = outcome()
        return response

    def _on_step(self, request, response):
        if not self._node.paused:
            response.result = outcome(Result.RESULT_INCORRECT_STATE,
                                      'the simulation is playing; pause it first')
            return response
        self._stopped = False
        ok, message = self._node.sim_services.take_steps(int(request.steps))
        response.result = outcome() if ok else outcome(Result.RESULT_OPERATION_FAILED, message)
        return response

    def _on_simulate(self, goal_handle):
        """The SimulateSteps action: ``step_simulation`` with progress and cancel."""
        result = SimulateSteps.Result()
        steps = int(goal_handle.request.steps)
        if not self._node.paused:
            result.result = outcome(Result.RESULT_INCORRECT_STATE,
                                    'the simulation is playing; pause it first')
            goal_handle.abort()
            return result
        self._stopped = False

        def progress(taken: int, total: int) -> None:
            goal_handle.publish_feedback(SimulateSteps.Feedback(
                completed_steps=taken, remaining_steps=total - taken))
        ok, message = self._node.sim_services.take_steps(
            steps, progress, lambda: goal_handle.is_cancel_requested, FEEDBACK_PERIOD)
        if ok:
            progress(steps, steps)
            result.result = outcome()
            goal_handle.succeed()
        elif goal_handle.is_cancel_requested:
            result.result = outcome(Result.RESULT_OPERATION_FAILED, message)
            goal_handle.canceled()
        else:
            result.result = outcome(Result.RESULT_OPERATION_FAILED, message)
            goal_handle.abort()
        return result

    def _on_get_state(self, request, response):
        response.state = SimulationState(state=self.state)
        response.result = outcome()
        return response

    def _on_set_state(self, request, response):
        target, current = request.state.state, self.state
        name = STATE_NAMES.get(target, str(target))
        if target == current:
            response.result = outcome(SetSimulationState.Response.ALREADY_IN_TARGET_STATE,
                                      f'the simulation is already {name}')
        elif target == SimulationState.STATE_PLAYING:
            self._stopped = False
            self._node.sim_services.set_paused(False, 'set_simulation_state')
            response.result = outcome()
        elif target == SimulationState.STATE_PAUSED:
            self._stopped = False
            self._node.sim_services.set_paused(True, 'set_simulation_state')
            response.result = outcome()
        elif target == SimulationState.STATE_STOPPED:
            self._node.sim_services.set_paused(True, 'set_simulation_state')
            self._node.reset_simulation('the simulation was stopped (set_simulation_state)')
            self._stopped = True
            response.result = outcome()
        else:
            response.result = outcome(SetSimulationState.Response.INCORRECT_TRANSITION,
                                      f'cannot go to state {name}: only PLAYING, PAUSED and '
                                      'STOPPED are supported')
        return response
