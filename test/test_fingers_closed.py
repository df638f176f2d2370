"""Deformable fingers that the jaws close on each other over the fruit.

The model has no contact between the two fingers. A firm close of the Fin Ray on the
small, soft tomato (60 mm, shell) brings the fingers' rigid bases together over its top,
whose outline is pinched between their front corners: no step can start without
crossing it. Such a run ends as 'pinched' (crushed at the pinch), not as a solver
failure, and the grasp window counts it as damage.
"""
from dataclasses import replace

import numpy as np
import pytest

from gripper_sim.core.barrier import BarrierContact, BarrierSettings, SoftBody
from gripper_sim.errors import FingersClosed
from gripper_sim.workflows.grasp import PINCH, PINCHED
from gripper_sim.workflows.window import trial_of, upper_bound_limited_by


def test_the_bodies_gap_is_the_nearest_two_outline_vertices_of_different_bodies():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [3.0, 0.5], [3.0, 2.0],
                  [1.5, 1.4], [2.0, 3.0]])
    bodies = (SoftBody(np.array([2, 3]), np.array([[2, 3]]), 0.5, 0.4),
              SoftBody(np.array([4, 5]), np.array([[4, 5]]), 0.5, 0.4),
              SoftBody(np.array([6, 7]), np.array([[6, 7]]), 0.5, 0.4))
    barrier = BarrierContact(8, np.arange(2), np.array([[0, 1]]),
                             BarrierSettings(dhat=1e-3, stiffness=0.1), bodies=bodies)
    # the fruit's nodes 0, 1 do not count; bodies 0 and 2 are nearest: (1, 1) to (1.5, 1.4)
    assert barrier.bodies_gap(x) == pytest.approx(np.hypot(0.5, 0.4))
    lone = BarrierContact(8, np.arange(2), np.array([[0, 1]]),
                          BarrierSettings(dhat=1e-3, stiffness=0.1), bodies=bodies[:1])
    assert lone.bodies_gap(x) == np.inf


@pytest.fixture(scope='module')
def pinched_trial():
    """The tomato's window trial at 50 N (bruise kind): the jaws close the Fin Ray fingers'
    bases onto each other over its top at 44 N of grip."""
    from gripper_sim.workflows.scenario import load_scenario, scenario_config
    from gripper_sim.workflows.window import evaluate_grasp, trial_setup
    scenario = load_scenario('pick_and_place')
    config, base = trial_setup(scenario_config(scenario, fruit='tomato', finger='fin_ray'),
                               scenario)
    return evaluate_grasp(config, base, 50.061, 'bruise')


def test_fingers_closed_on_the_fruit_pinch_it(pinched_trial):
    evaluation = pinched_trial
    assert evaluation.outcome == PINCHED
    assert evaluation.crushed and evaluation.bruised and evaluation.bruised_at == PINCH
    assert not evaluation.dropped and not evaluation.held
    assert isinstance(evaluation.failure, FingersClosed)
    assert evaluation.failure.gap < 1e-5
    assert 'fingers closed on each other over the fruit' in evaluation.message
    assert 40.0 < evaluation.peak_grip_force < 50.0  # the jaws stopped short of 50 N


def test_the_window_counts_a_pinch_as_damage_not_a_solver_failure(pinched_trial):
    pinched = trial_of(pinched_trial, 'bruise')
    assert pinched.bruised and not pinched.held and pinched.verdict == PINCHED
    safe = replace(pinched, force=40.0, outcome='held', bruised=False, bruised_at=None)
    assert upper_bound_limited_by(40.0, [safe, pinched]) == 'bruise'
