"""Shared set-ups of the mechanics tests."""
from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation

#: quasi-static settings: light fruit, mass damping, large step, no gravity, no table
QUASI_STATIC = ['world.gravity=0', 'world.table=false', 'fruit.density=50',
                'fruit.damping.mass=20', 'sim.dt=0.01', 'fruit.depth=0.01']


def quasi_static_sim(radius: float, *overrides: str) -> Simulation:
    config = load_config(overrides=QUASI_STATIC + [
        f'fruit.shape.diameter={2 * radius}', f'gripper.initial_gap={2 * radius + 1e-4}',
        *overrides])
    return Simulation(config)
