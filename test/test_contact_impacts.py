"""Impacts with restitution: no energy gain, rebounds from two faces at once, and drops
that converge; the numba fast path and the numpy reference path agree on each case."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConvergenceError
from gripper_sim.workflows.factory import make_simulation

from reference_solver import reference_route

#: a coarse 3D shell (162 nodes), as in test_3d_validation
COARSE_3D = ['dimension=3', 'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=1']
#: J per J of m g h: what "never rises" allows for rounding
ENERGY_SLACK = 1e-4


def _total(result) -> float:
    energies = result.energies
    return energies.kinetic + energies.elastic + energies.gravitational


def _dropped(overrides, height, **kwargs):
    """The fruit, out of the jaws' reach, with its centre ``height`` (m) above where it
    rests on the table."""
    base = list(overrides) + ['gripper.initial_lift=5']
    resting = make_simulation(load_config(overrides=base), **kwargs).last.centroid[-1]
    return make_simulation(load_config(overrides=base + [
        f'fruit.initial_height={resting + height}']), **kwargs)


def _energy_rises(sims, duration, height):
    """Step the simulations side by side for ``duration`` s; the largest rise of total
    energy over one step, per m g h, of each, and their largest position difference (m)."""
    sim = sims[0]
    mgh = sim.fruit.total_mass * sim.config['world.gravity'] * height
    before = [_total(s.last) for s in sims]
    rises = [-np.inf] * len(sims)
    apart = 0.0
    impacts = 0
    for _ in range(int(round(duration / sim.dt))):
        results = [s.step() for s in sims]
        for k, result in enumerate(results):
            total = _total(result)
            rises[k] = max(rises[k], (total - before[k]) / mgh)
            before[k] = total
        apart = max(apart, float(np.max(np.abs(results[0].positions
                                               - results[-1].positions))))
        impacts += bool(np.any(results[0].contact_obstacle >= 0))
    assert impacts > 0, 'the fruit never reached the table'
    return rises, apart


@pytest.mark.parametrize('restitution, both_paths', [(0.3, False), (0.6, False),
                                                     (0.9, True)])
def test_total_energy_never_rises_across_an_impact_in_2d(restitution, both_paths):
    # a 2D shell dropped 5 cm: the impact step gained 10 % of m g h at e = 0.8 when the
    # rebound was prescribed as a position (0.7 % at e = 0.9, later); the fast path, and
    # at e = 0.9 the reference path side by side with it
    overrides = [f'contact.restitution={restitution}']
    sims = [_dropped(overrides, 0.05, fast=True)]
    if both_paths:
        sims.append(reference_route(_dropped(overrides, 0.05, fast=False)))
    rises, apart = _energy_rises(sims, 0.3, 0.05)
    assert max(rises) < ENERGY_SLACK, rises
    assert apart < 1e-9


@pytest.mark.parametrize('restitution', [0.3, 0.6, 0.9])
def test_total_energy_never_rises_across_an_impact_in_3d(restitution):
    sim = _dropped(COARSE_3D + ['sim.dt=0.005', f'contact.restitution={restitution}'], 0.05)
    (rise,), _ = _energy_rises([sim], 0.25, 0.05)
    assert rise < ENERGY_SLACK


def _corner_shot(fast: bool, restitution: float = 0.6, speed: float = 0.5):
    """A point fruit flying at (speed, -speed) m/s into the corner of the table and the
    right wall, reaching both half way through step 11."""
    dt = 1e-3
    meet = 10.5 * dt
    config = load_config(overrides=[
        'fruit.model=point', f'sim.dt={dt}', f'contact.restitution={restitution}',
        f'fruit.initial_height={speed * meet + 0.5 * 9.81 * meet ** 2}',
        'gripper.initial_lift=5', 'world.walls=true', f'world.wall_half_width={speed * meet}',
        f'fruit.initial_velocity.x={speed}', f'fruit.initial_velocity.z={-speed}'])
    return Simulation(config, fast=fast)


@pytest.mark.parametrize('fast', [True, False])
def test_a_node_hitting_floor_and_wall_in_one_step_rebounds_from_both(fast):
    restitution, speed = 0.6, 0.5
    sim = _corner_shot(fast, restitution, speed)
    for _ in range(10):
        incoming = sim.step().velocities[0]
    assert incoming[0] == pytest.approx(speed) and incoming[1] < -speed
    result = sim.step()
    assert result.contact_obstacle[0] == -1  # released after its rebound
    vx, vz = result.velocities[0]
    assert vx == pytest.approx(-restitution * speed, rel=1e-6)  # the wall's rebound
    # the table's: e times the speed at the moment of contact, half a step of gravity on
    approach = -incoming[1] + 0.5 * 9.81 * sim.dt
    assert vz == pytest.approx(restitution * approach, rel=0.02)
    later = sim.step()
    assert later.positions[0, 0] < result.positions[0, 0]  # away from the wall
    assert later.positions[0, 1] > result.positions[0, 1]  # and off the table


def test_both_paths_agree_on_the_corner_rebound():
    fast_sim, reference = _corner_shot(True), _corner_shot(False)
    for _ in range(40):
        a, b = fast_sim.step(), reference.step()
        np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.velocities, b.velocities, rtol=0, atol=1e-9)


@pytest.mark.parametrize('fruit, restitution, sideways', [
    ('apple', 0.0, 0.0),    # the default apple
    ('apple', 0.9, 0.3),
    ('orange', 0.9, 0.3),   # a friction ping-pong in Newton failed these
    ('plum', 0.0, 0.3),
])
def test_a_one_metre_drop_completes_at_dt_1e_3(fruit, restitution, sideways):
    config = load_config(fruit=fruit, overrides=[
        'sim.dt=1e-3', 'fruit.initial_height=1.0', f'contact.restitution={restitution}',
        f'fruit.initial_velocity.x={sideways}'])
    sim = Simulation(config)
    on_table = 0
    for _ in range(650):  # the impact is at 0.44 s
        on_table += bool(np.any(sim.step().contact_obstacle >= 0))
    assert on_table > 0
    assert np.all(np.isfinite(sim.last.positions))


def test_a_step_that_fails_in_its_smallest_substeps_names_what_helps():
    config = load_config(overrides=['fruit.nodes=32', 'sim.max_newton_iterations=3',
                                    'gripper.initial_gap=0.0645', 'gripper.close_speed=0.1'])
    sim = Simulation(config)
    sim.command_gap(0.03)  # the jaws hit the fruit at full speed
    with pytest.raises(ConvergenceError, match='sim.max_newton_iterations') as caught:
        sim.run(0.2)
    message = str(caught.value)
    assert 'now 3' in message and 'sim.max_halvings (now 6)' in message
    assert 'sub-steps of 1.56e-05 s' in message
