"""The bruise estimates agree with what the simulation finds, contact by contact: with a
soft pad the jaw contact is spared (its Hertz estimate is far above the flat finger's)
and the fruit, squeezed on the table, bruises at the table once the table carries its
own Hertz bruise load."""
import pytest

from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import evaluate
from gripper_sim.workflows.scenario import PickAndPlace, load_scenario, scenario_config
from gripper_sim.workflows.window import estimates, table_bruise_load, trial_of, trial_setup


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
