"""A failing solver step: the node reports it, publishes no NaN, resets and goes on.

In-process node driven step by step (no physics thread), with a simulation that fails
on purpose: a ConvergenceError, or a step that returns non-finite values.
"""
import dataclasses
import math

import numpy as np
import pytest
import rclpy

from gripper_sim.convert import messages
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConvergenceError
from gripper_sim.ros.node import SimNode
from gripper_sim.ros.process import pick_domain_id
from gripper_sim.ros.sync import JawOwner
from ros_client import ros_context

pytestmark = pytest.mark.ros


class FailingSimulation(Simulation):
    """Fails step number ``fail_at`` (counted over its life) in the way ``mode`` says."""

    fail_at = 5
    mode = 'converge'

    def __init__(self, config):
        super().__init__(config)
        self.calls = 0

    def step(self):
        self.calls += 1
        if self.calls != self.fail_at:
            return super().step()
        if self.mode == 'converge':
            raise ConvergenceError('injected failure', residual_history=[1.0, 2.0],
                                   time=self.time)
        result = super().step()
        positions = result.positions.copy()
        positions[0, 0] = float('nan')
        return dataclasses.replace(result, positions=positions)


class Owner(JawOwner):
    kind = 'Grasp'

    def __init__(self):
        self.reasons = []

    def abort(self, reason):
        self.reasons.append(reason)


@pytest.fixture
def context():
    with ros_context(pick_domain_id(30)) as context:
        yield context


@pytest.mark.parametrize('mode', ['converge', 'nan'])
def test_a_failed_step_is_reported_resets_and_publishes_nothing_non_finite(context, mode):
    FailingSimulation.mode = mode
    node = SimNode(context=context, simulation_factory=FailingSimulation, start=False,
                   parameter_overrides=[rclpy.parameter.Parameter('publish_rate', value=1000.0),
                                        rclpy.parameter.Parameter('foxglove_port', value=0)])
    try:
        published = []
        node.add_publish_observer(lambda batch, stamp: published.append(batch))
        resets = []
        node.add_reset_listener(resets.append)
        owner = Owner()
        assert node.claim_jaws(owner, node.jaws.ticket()) is None
        node.sim.command_gap(0.06)
        results = [node.advance() for _ in range(8)]
        assert results[4] is None and all(r is not None for r in results[:4] + results[5:])
        assert node.failures == 1
        assert len(resets) == 1 and resets[0].time == 0.0   # the recorder's hook
        assert len(owner.reasons) == 1 and 'failed step' in owner.reasons[0]
        # reset to t = 0 and went on: 3 steps after the failure
        assert node.sim.time == pytest.approx(0.003)
        assert node.sim.last.gap == pytest.approx(0.0735, abs=1e-9)   # commands reset too
        assert published, 'nothing was published'
        for batch in published:
            state = batch['fruit/state']
            assert all(math.isfinite(getattr(state, f)) for f in
                       ('gap', 'grip_force', 'compression', 'elastic_energy'))
            assert np.all(np.isfinite(messages.read_point_cloud(batch['fruit/nodes'])))
        # steps 1-4, the failed step 5 is not published, the reset state, steps 1-3
        times = [b['clock'].clock.nanosec // 1_000_000 for b in published]
        assert times == [1, 2, 3, 4, 0, 1, 2, 3]
    finally:
        node.destroy_node()
