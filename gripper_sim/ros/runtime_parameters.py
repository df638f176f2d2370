"""Parameter changes while the node runs: what each accepted change does to the node.

``publish_rate``, ``clock_rate``, ``marker_rate``, ``real_time_factor`` and
``publish_clock`` act at once; a dynamic
``physics.*`` key is queued for the physics thread (``sim.set_parameter``) like a
command. ``log_rejections`` puts rclpy's own refusals (range, type, read-only) in the
node's log, which rclpy does not.
"""
from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import SetParametersResult

from gripper_sim.ros.params import PHYSICS_PREFIX, physics_changes


class RuntimeParameters:
    """Applies accepted parameter changes to ``node`` (a ``SimNode``)."""

    def __init__(self, node):
        self._node = node
        node.params.on_change(self._on_changed)
        node.add_on_set_parameters_callback(self._check_runtime_physics)

    def _check_runtime_physics(self, parameters) -> SetParametersResult:
        node = self._node
        changes = physics_changes({p.name: p.value for p in parameters})
        if changes and not hasattr(node.sim, 'set_parameter'):
            reason = (f"this simulation core cannot change {', '.join(sorted(changes))} "
                      'while running; set it at start-up')
            node.get_logger().warning(f'parameter change rejected: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_changed(self, changes: dict[str, Any]) -> None:
        node = self._node
        if 'publish_rate' in changes:
            node.state_publisher.set_rate(float(changes['publish_rate']), node.sim.dt)
        if 'clock_rate' in changes:
            node.state_publisher.set_rate(float(changes['clock_rate']), node.sim.dt, 'clock')
        if 'marker_rate' in changes:
            node.state_publisher.set_rate(float(changes['marker_rate']), node.sim.dt,
                                          'markers')
        if 'real_time_factor' in changes:
            node.physics.set_real_time_factor(float(changes['real_time_factor']))
        if 'publish_clock' in changes:
            node.state_publisher.publish_clock = bool(changes['publish_clock'])
        for key, value in physics_changes(changes).items():
            node.commands.put(f'parameter change {PHYSICS_PREFIX}{key} = {value}',
                              lambda key=key, value=value: node.sim.set_parameter(key, value),
                              slot=PHYSICS_PREFIX + key)
        node.get_logger().info(f'parameters changed: {changes}')


def log_rejections(logger, parameter_list, results) -> None:
    """Log each distinct reason rclpy gave for refusing a parameter change."""
    logged = set()
    for parameter, result in zip(parameter_list, results):
        if not result.successful and result.reason not in logged:
            logged.add(result.reason)
            if not result.reason.startswith(('parameter ', 'this simulation core')):
                # rclpy's own checks (range, type, read-only) are not logged by it
                logger.warning(
                    f"parameter change of '{parameter.name}' rejected: {result.reason}")
