"""Bouncing and resting contact (the seed's bouncing node), friction hold and slip."""
import numpy as np
import pytest

from helpers import RESTITUTION, bounce_apex_ratios, bouncing_node, pick



@pytest.mark.parametrize('dt', [1e-3, 1e-4])
def test_bounce_apex_heights_fall_by_restitution_squared(dt):
    ratios = bounce_apex_ratios(dt)
    assert len(ratios) == 4
    assert np.all(np.abs(ratios / RESTITUTION ** 2 - 1) < 0.02), ratios


@pytest.mark.parametrize('dt', [1e-3, 1e-4])
def test_resting_node_reaction_equals_weight_without_chatter(dt):
    sim = bouncing_node(dt)
    sim.run(12.0)
    weight = sim.fruit.total_mass * 9.81
    heights, reactions = [], []
    for _ in range(int(0.5 / dt)):
        result = sim.step()
        heights.append(result.positions[0, 1])
        reactions.append(result.contact_forces[0, 1])
    reactions = np.array(reactions)
    assert np.all(np.abs(reactions / weight - 1) < 0.01)
    assert np.ptp(heights) < 1e-9, 'the node still bounces at rest'
    # on the frictionless table it may still slide from wall to wall (each wall sends it
    # back with e times its speed), but it no longer moves vertically
    assert result.velocities[0, 1] == pytest.approx(0.0, abs=1e-9)


def test_fruit_is_held_when_friction_exceeds_weight():
    sim, summary = pick(1.2)
    assert summary['outcome'] == 'held'
    assert summary['slip_distance'] < 1e-3
    assert sim.last.centroid[1] > sim.initial_positions[:, 1].mean() + 0.015


def test_fruit_slips_when_friction_is_below_weight():
    sim, summary = pick(0.8)
    assert summary['outcome'] in ('slipped', 'dropped')
    assert summary['slip_distance'] > 5e-3
    assert sim.last.centroid[1] < sim.initial_positions[:, 1].mean() + 0.005
