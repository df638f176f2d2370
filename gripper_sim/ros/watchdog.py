"""The physics watchdog: a stalled or dead physics loop is logged, published and restarted.

Once a second (a timer of the node) the watchdog looks at the physics loop's
``heartbeat``. No progress for ``stall_timeout`` wall seconds (a step that does not
return, the simulation lock held elsewhere) is a stall: an error in the log and an
ERROR status on ``/diagnostics``, and a log line again when the loop runs again. A
physics thread that has ended although the node was not stopped is started anew.
The status (``diagnostic_msgs/DiagnosticArray``, one ``DiagnosticStatus`` named
``<node>: physics``) goes out on every check, with the sim time, the real-time
factors, the steps taken, and the errors the loop survived.
"""
from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

# No progress of the physics loop for this long (wall s) is a stall.
STALL_TIMEOUT = 10.0   # s
CHECK_PERIOD = 1.0     # s of wall time


class PhysicsWatchdog:
    """Watches ``node.physics`` (a ``PhysicsLoop``) and reports on ``/diagnostics``.

    Args:
        node: the ``SimNode``.
        stall_timeout: wall s without progress that make a stall.
        period: wall s between checks (a timer of ``node``); 0 = no timer (call ``check``).
    """

    def __init__(self, node, stall_timeout: float = STALL_TIMEOUT,
                 period: float = CHECK_PERIOD):
        self._node = node
        self.stall_timeout = stall_timeout
        self._publisher = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._name = f'{node.get_fully_qualified_name()}: physics'
        self.stalled_since: float | None = None
        self.stalls = 0
        if period > 0:
            node.create_timer(period, self.check,
                              callback_group=MutuallyExclusiveCallbackGroup())

    def check(self) -> DiagnosticStatus:
        """Look at the loop once: restart a dead thread, detect a stall; publish."""
        node = self._node
        loop = node.physics
        logger = node.get_logger()
        level, message = DiagnosticStatus.OK, 'running'
        if loop.stopped:
            level, message = DiagnosticStatus.OK, 'stopped'
        elif loop.started and not loop.alive:
            logger.error('the physics thread has ended; starting it again')
            loop.restart()
            level, message = DiagnosticStatus.ERROR, 'the physics thread had ended: restarted'
        else:
            quiet = time.monotonic() - loop.heartbeat
            if quiet > self.stall_timeout:
                if self.stalled_since is None:
                    self.stalled_since = loop.heartbeat
                    self.stalls += 1
                    logger.error(
                        f'the physics loop is stalled: no progress for {quiet:.1f} s at sim '
                        f't = {node.sim.time:.4f} s (a step that does not return, or the '
                        'simulation lock held elsewhere); services still answer')
                level = DiagnosticStatus.ERROR
                message = f'stalled: no progress for {quiet:.1f} s'
            elif self.stalled_since is not None:
                logger.warning(f'the physics loop runs again after a stall of '
                               f'{time.monotonic() - self.stalled_since:.1f} s')
                self.stalled_since = None
            elif loop.paused:
                message = 'paused'
        status = DiagnosticStatus(level=level, name=self._name, message=message,
                                  hardware_id=node.get_fully_qualified_name())
        status.values = [KeyValue(key=key, value=value) for key, value in (
            ('sim_time', f'{node.sim.time:.6f}'),
            ('real_time_factor', f'{loop.real_time_factor:g}'),
            ('achieved_real_time_factor', _number(loop.achieved_rtf)),
            ('steps_taken', str(node.steps_taken)),
            ('failed_steps', str(node.failures)),
            ('loop_errors', str(loop.errors)),
            ('thread_restarts', str(loop.restarts)),
            ('stalls', str(self.stalls)))]
        array = DiagnosticArray(status=[status])
        array.header.stamp = node.get_clock().now().to_msg()
        self._publisher.publish(array)
        return status


def _number(value: float) -> str:
    return f'{value:.3g}' if math.isfinite(value) else 'unknown'
