"""The bruise estimates agree with what the simulation finds, contact by contact: with a
soft pad the jaw contact is spared (its Hertz estimate is far above the flat finger's)
and the fruit, squeezed on the table, bruises at the table once the table carries its
own Hertz bruise load."""
import math

import pytest

from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import evaluate
from gripper_sim.workflows.scenario import PickAndPlace, load_scenario, scenario_config
from gripper_sim.workflows.window import (GraspWindow, Trial, estimates, table_bruise_load,
                                          trial_of, trial_setup)


def bruise_trial(finger: str, force: float):
    """A 'bruise' window trial at ``force`` N; (trial, the damage contacts of the step at
    which it first bruised as {obstacle: (load N, p0 Pa)}, the bruise estimates)."""
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, finger=finger)
    jaw_estimate = estimates(config)[1]
    table_estimate = table_bruise_load(config)
    config, base = trial_setup(config, scenario)
    sim = make_simulation(config)
    machine = PickAndPlace(sim, base.with_values(close__mode='force', close__force=force),
                           until='transport', stop_on_bruise=True)
    seen = {}

    def on_step(result, _phase):
        if result.damage.bruised and not seen:
            for contact in result.damage.contacts:
                name = result.obstacle_names[contact.body].split('.')[0]
                seen[name] = (contact.load, contact.peak_pressure)
    trial = trial_of(evaluate(sim, machine, force, on_step), 'bruise')
    return trial, seen, jaw_estimate, table_estimate, config['fruit.bruise_pressure']


def test_under_a_soft_pad_the_fruit_bruises_at_the_table_where_its_estimate_says():
    trial, contacts, jaw_estimate, table_estimate, threshold = bruise_trial('soft_pad', 30.0)
    assert trial.bruised and trial.bruised_at == 'table'
    load, p0 = contacts['table']
    assert p0 > threshold and load == pytest.approx(table_estimate, rel=0.03)
    # the jaws are far from bruising, and their Hertz estimate is the one the simulation
    # follows there: F_b = F (p_b / p0)^3
    jaw_load, jaw_p0 = contacts['left_jaw']
    assert jaw_p0 < 0.7 * threshold
    assert jaw_load * (threshold / jaw_p0) ** 3 == pytest.approx(jaw_estimate, rel=0.03)
    assert jaw_estimate > 4 * table_estimate


def test_on_rigid_flat_jaws_the_jaws_bruise_first_at_their_estimate():
    trial, contacts, jaw_estimate, _table, threshold = bruise_trial('flat', 20.0)
    assert trial.bruised and trial.bruised_at == 'jaws'
    load, p0 = contacts['left_jaw']
    assert p0 > threshold and load == pytest.approx(jaw_estimate, rel=0.03)


def _trial(force, kind, outcome, bruised):
    return Trial(force=force, kind=kind, held=False, slipped=True, bruised=bruised,
                 outcome=outcome, slip_distance=0.0, peak_grip_force=force,
                 peak_jaw_pressure=0.0, peak_table_pressure=0.0, peak_damage_pressure=0.0,
                 bruised_at=None, wall_time=0.0)


@pytest.mark.parametrize('above, limited_by', [('bruised', 'bruise'),
                                                ('solver failed', 'solver failure')])
def test_the_window_says_whether_a_bruise_or_a_solver_failure_ended_its_safe_side(
        above, limited_by):
    """A bruise trial whose solver failed reads 'solver failed', not 'bruised', and a
    window whose upper bound sits below such a trial says so (text and JSON)."""
    trials = [_trial(10.0, 'bruise', 'held', False), _trial(20.0, 'bruise', above, True),
              _trial(15.0, 'bruise', 'held', False), _trial(30.0, 'bruise', 'bruised', True)]
    window = GraspWindow(fruit='apple', finger='fin_ray', min_force=2.0, max_force=15.0,
                         min_estimate=1.0, max_estimate=16.0, mass=0.134, friction=0.5,
                         tolerance=0.05, trials=trials)
    assert trials[1].verdict == ('bruised' if above == 'bruised' else 'solver failed')
    assert window.max_force_limited_by == limited_by
    assert window.as_dict()['max_force_limited_by'] == limited_by
    assert GraspWindow(fruit='apple', finger='fin_ray', min_force=2.0, max_force=math.inf,
                       min_estimate=1.0, max_estimate=16.0, mass=0.134, friction=0.5,
                       tolerance=0.05, trials=trials).max_force_limited_by is None
