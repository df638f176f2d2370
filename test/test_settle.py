"""A fruit that starts on the table has settled on it under its weight before t = 0
(``SimulationFacade._settle``, 2D and 3D): its first step finds it at rest, the table carrying
its weight, whatever the fruit model, contact model and finger; a fruit placed at a
height starts undeformed there; a fruit that does not come to rest is a clear
configuration error, on the command line one line."""
from __future__ import annotations

import numpy as np
import pytest

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config
from gripper_sim.core import facade
from gripper_sim.errors import ConfigError, ConvergenceError
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.scenario import rest_shape

GRAVITY = 9.81


def table_force(result) -> float:
    """N, the table's vertical force on the fruit in a step's result."""
    table = result.contact_obstacle == result.obstacle_names.index('table')
    return float(result.contact_forces[table, -1].sum())


@pytest.mark.parametrize('overrides', [[], ['fruit.model=solid'], ['contact.model=ipc'],
                                       ['gripper.finger.type=fin_ray']],
                         ids=['shell', 'solid', 'ipc', 'fin_ray'])
def test_the_first_step_finds_the_fruit_at_rest_on_the_table(overrides):
    sim = make_simulation(load_config(overrides=overrides))
    start = sim.q.copy()
    result = sim.step()
    weight = sim.fruit.total_mass * GRAVITY
    assert table_force(result) == pytest.approx(weight, rel=1e-3)
    assert np.abs(result.velocities).max() < 1e-4          # m/s: still
    assert np.abs(sim.q - start).max() < 1e-7              # m: a tenth of a micrometre


@pytest.mark.parametrize('overrides', [[], ['fruit.model=solid'], ['contact.model=ipc']],
                         ids=['shell', 'solid', 'ipc'])
def test_a_3d_fruit_starts_resting_on_the_table_where_it_was_placed(overrides):
    """The 3D settle (``Simulation3D``, its rolling held: ``core3d.rolling_hold``): the
    first step's table force is the fruit's weight (it landed with 0.82 m g at its first
    step, 1.15 m g at its peak, before), the nodes are near still (3.7e-2 m/s landing),
    and the settle did not roll it: its centroid within 1 um of the placement (settled
    unheld the shell rolls 0.11 mm aside, the solid apple 3 mm)."""
    sim = make_simulation(load_config(overrides=['dimension=3', *overrides]))
    centroid = sim.q[:sim.fruit.n_nodes].mean(axis=0)
    result = sim.step()
    weight = sim.fruit.total_mass * GRAVITY
    assert table_force(result) == pytest.approx(weight, rel=3e-3)
    assert np.abs(result.velocities).max() < 2e-3           # m/s
    assert np.abs(centroid[:2]).max() < 1e-6                # m


def test_the_settled_apple_is_flattened_by_its_weight_and_stays_centred():
    sim = make_simulation(load_config())
    rest = rest_shape(sim.config).rest_positions
    settled = sim.initial_positions
    height = settled[:, 1].max() - settled[:, 1].min()
    width = settled[:, 0].max() - settled[:, 0].min()
    rest_height = rest[:, 1].max() - rest[:, 1].min()
    assert 1e-4 < rest_height - height < 1e-3               # m: squashed a fraction of a mm
    assert width > rest[:, 0].max() - rest[:, 0].min()      # and bulges
    assert abs(settled[:, 0].mean()) < 1e-9                 # not rolled


def test_a_fruit_placed_at_a_height_starts_undeformed_there():
    config = load_config(overrides=['fruit.initial_height=0.2'])
    sim = make_simulation(config)
    rest = rest_shape(config).rest_positions
    assert np.array_equal(sim.initial_positions, rest + np.array([0.0, 0.2]))


def test_a_settling_step_that_fails_is_tried_again_shorter(monkeypatch):
    """Steps longer than 8 ms fail here: the settle goes on with shorter ones and ends at
    rest as with longer ones."""
    reference = make_simulation(load_config()).initial_positions
    advance = facade.SimulationFacade._advance
    tried = []

    def short_steps_only(sim, dt, depth):
        tried.append(dt)
        if dt > 0.008 + 1e-12:
            raise ConvergenceError('too long a step')
        return advance(sim, dt, depth)

    monkeypatch.setattr(facade.SimulationFacade, '_advance', short_steps_only)
    sim = make_simulation(load_config())
    assert max(tried) > 0.008                       # it tried longer steps and went on
    assert np.abs(sim.initial_positions - reference).max() < 1e-6
    assert sim.step().velocities.max() < 1e-4


def test_a_fruit_that_does_not_come_to_rest_is_a_configuration_error(monkeypatch, capsys):
    monkeypatch.setattr(facade, 'SETTLE_MAX_STEPS', 2)
    with pytest.raises(ConfigError, match="does not come to rest.*'fruit.initial_height'"):
        make_simulation(load_config())
    assert main(['pick', '--force', '3']) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('error: '), lines
    assert 'does not come to rest on the table' in lines[0]


def test_a_settling_step_that_fails_at_the_time_step_is_a_configuration_error(monkeypatch):
    def fails(sim, dt, depth):
        raise ConvergenceError('no convergence')

    monkeypatch.setattr(facade.SimulationFacade, '_advance', fails)
    with pytest.raises(ConfigError, match=r"does not come to rest .*\(no convergence\)"):
        make_simulation(load_config())
    make_simulation(load_config(overrides=['fruit.initial_height=0.2']))   # no settle
