"""The grasp window, by simulation: the rigid flat finger's minimum is m g / (2 mu);
every fruit of the library is placed inside its window and dropped or bruised outside."""
import json
import math

import pytest

from gripper_sim.core.simulation import Simulation
from gripper_sim.workflows.scenario import load_scenario, run_scenario, scenario_config
from gripper_sim.workflows.window import _bisect, grasp_window
from test_cli_offline import gripper_sim

LIBRARY = ('apple', 'tomato', 'peach', 'orange', 'plum', 'strawberry')


def test_bisection_finds_a_boundary_outside_its_first_guess():
    calls = []

    def holds(force):
        calls.append(force)
        return force >= 7.3
    found = _bisect(holds, 1.0, 2.0, 100.0, 0.01, want_smallest=True)
    assert 7.3 <= found <= 7.3 * 1.01 + 1e-12
    bruises_above = _bisect(lambda f: f <= 0.42, 1.0, 2.0, 100.0, 0.01, want_smallest=False)
    assert 0.42 * 0.99 <= bruises_above <= 0.42
    assert _bisect(lambda f: f < 1e9, 1.0, 2.0, 100.0, 0.01, want_smallest=False) == math.inf
    assert _bisect(lambda f: False, 1.0, 2.0, 100.0, 0.01, want_smallest=True) is None


def test_bisection_widens_all_the_way_to_the_limit():
    """A first guess far below the boundary (the 3D shell bruises at ~1000 x its Hertz
    estimate): the bracket doubles up to the limit instead of giving up after a few
    widenings and calling everything below the limit safe."""
    tried = []

    def safe(force):
        tried.append(force)
        return force <= 50.0
    found = _bisect(safe, 0.01, 0.02, 200.0, 0.01, want_smallest=False)
    assert 50.0 * 0.99 <= found <= 50.0
    assert _bisect(lambda f: True, 0.01, 0.02, 200.0, 0.01, want_smallest=False) == math.inf
    holds_from = _bisect(lambda f: f >= 150.0, 0.01, 0.02, 200.0, 0.01, want_smallest=True)
    assert 150.0 <= holds_from <= 150.0 * 1.01


@pytest.mark.slow
def test_rigid_flat_finger_minimum_is_m_g_over_2_mu():
    """validation.md section 6 (one friction coefficient: mu_k = mu_s = 0.5)."""
    run = gripper_sim('window', '--fruit', 'apple', '--finger', 'flat', '--json',
                      '--set', 'contact.jaw.static_friction=0.5',
                      '--set', 'contact.jaw.kinetic_friction=0.5')
    assert run.returncode == 0, run.stderr
    window = json.loads(run.stdout)
    mass, mu = window['mass'], window['friction']
    assert mu == 0.5
    expected = mass * 9.81 / (2 * mu)
    assert window['min_force'] == pytest.approx(expected, rel=0.10)
    assert window['window'] is True
    assert window['min_force'] < window['max_force']
    # the bisections bracket their answers with simulations on both sides
    held = [t['force'] for t in window['trials'] if t['held']]
    assert min(held) == window['min_force']
    assert any(not t['held'] and t['force'] < window['min_force'] for t in window['trials'])
    assert any(t['bruised'] and t['force'] > window['max_force'] for t in window['trials'])


@pytest.mark.slow
@pytest.mark.parametrize('fruit', LIBRARY)
def test_fruit_is_placed_inside_its_window_and_not_outside(fruit):
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, fruit=fruit)
    window = grasp_window(config, scenario, tolerance=0.25)
    assert window.exists, window.as_dict()
    assert math.isfinite(window.max_force), 'no bruising up to gripper.max_force'
    inside = math.sqrt(window.min_force * window.max_force)
    # below: the largest force the window's own search saw drop the fruit
    dropped = [t.force for t in window.trials if t.outcome == 'dropped']
    assert dropped and max(dropped) < window.min_force
    below, above = max(dropped), 1.25 * window.max_force
    outcomes = {}
    for name, force in (('inside', inside), ('below', below), ('above', above)):
        sim = Simulation(config)
        outcomes[name] = run_scenario(sim, scenario.with_values(close__force=force))
    assert outcomes['inside']['outcome'] == 'placed', outcomes['inside']
    assert outcomes['below']['outcome'] in ('dropped', 'slipped'), outcomes['below']
    assert outcomes['below']['dropped'] or outcomes['below']['slipped']
    assert outcomes['above']['outcome'] in ('bruised', 'crushed'), outcomes['above']
