"""Bouncing and resting contact (the seed's bouncing node), friction hold and slip."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.grasp import GraspSequence, run_grasp
from gripper_sim.core.simulation import Simulation

RESTITUTION = 0.8


def _bouncing_node(dt):
    config = load_config(overrides=[
        'fruit.model=point', f'sim.dt={dt}', f'contact.restitution={RESTITUTION}',
        'fruit.initial_height=1.0', 'gripper.initial_lift=5', 'world.walls=true',
        'world.wall_half_width=0.3', 'fruit.initial_velocity.x=0.5',
        'contact.table.static_friction=0', 'contact.table.kinetic_friction=0'])
    return Simulation(config)


@pytest.mark.parametrize('dt', [1e-3, 1e-4])
def test_bounce_apex_heights_fall_by_restitution_squared(dt):
    sim = _bouncing_node(dt)
    z = np.array([sim.step().positions[0, 1] for _ in range(int(6.0 / dt))])
    inner = z[1:-1]
    apex = inner[(inner > z[:-2]) & (inner >= z[2:]) & (inner > 0.01)]
    assert len(apex) >= 5
    ratios = apex[1:5] / apex[:4]
    assert np.all(np.abs(ratios / RESTITUTION ** 2 - 1) < 0.02), ratios


@pytest.mark.parametrize('dt', [1e-3, 1e-4])
def test_resting_node_reaction_equals_weight_without_chatter(dt):
    sim = _bouncing_node(dt)
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
    assert np.all(result.velocities[0] == pytest.approx([0.0, 0.0], abs=1e-9))


def _pick(ratio):
    """Grip so that 2 mu N = ratio m g, lift 2 cm, hold 1 s."""
    config = load_config(overrides=['contact.jaw.static_friction=0.5',
                                    'contact.jaw.kinetic_friction=0.5'])
    sim = Simulation(config)
    weight = sim.fruit.total_mass * config['world.gravity']
    force = ratio * weight / (2 * 0.5)
    sequence = GraspSequence(sim, force, lift_height=0.02, hold_time=1.0)
    return sim, run_grasp(sim, sequence)


def test_fruit_is_held_when_friction_exceeds_weight():
    sim, summary = _pick(1.2)
    assert summary['outcome'] == 'held'
    assert summary['slip_distance'] < 1e-3
    assert sim.last.centroid[1] > sim.initial_positions[:, 1].mean() + 0.015


def test_fruit_slips_when_friction_is_below_weight():
    sim, summary = _pick(0.8)
    assert summary['outcome'] in ('slipped', 'dropped')
    assert summary['slip_distance'] > 5e-3
    assert sim.last.centroid[1] < sim.initial_positions[:, 1].mean() + 0.005
