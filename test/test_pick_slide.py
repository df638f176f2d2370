"""One slip measure for both grasp workflows: ``pick`` (``GraspSequence``) and ``run``
(``PickAndPlace``) integrate the jaw contacts' slide (``core.slip.ContactSlide``) and
report the centroid's drop relative to the jaws apart (``centroid_drop``)."""
import json
from types import SimpleNamespace

import numpy as np
import pytest

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config
from gripper_sim.core.multistep import Skipped
from gripper_sim.core.slip import SLIP_TOLERANCE, ContactSlide
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import SETTLE_TIME, GraspSequence, evaluate
from gripper_sim.workflows.scenario import PickAndPlace, load_scenario, scenario_config

NAMES = ('left_jaw', 'right_jaw', 'table')
DT = 0.01


def _result(time, vertical, obstacle, lift_velocity=0.05, drop=0.0, dimension=2):
    """A step result with what ``ContactSlide`` reads: node vertical velocities (m/s), the
    obstacle each node touches (-1 none), the lift velocity (m/s), the centroid drop (m)."""
    velocities = np.zeros((len(vertical), dimension))
    velocities[:, -1] = vertical
    velocities[:, 0] = 0.3  # along the closing axis: not a slide
    return SimpleNamespace(time=time, velocities=velocities, obstacle_names=NAMES,
                           contact_obstacle=np.array(obstacle), lift_velocity=lift_velocity,
                           slip_distance=drop)


@pytest.mark.parametrize('dimension', [2, 3])
def test_the_slide_counts_the_jaw_contacts_sliding_not_the_centroid_dropping(dimension):
    meter = ContactSlide(0.0)
    on = [0, 1, 2, -1]  # two nodes on the jaws, one on the table, one free
    for k in range(1, 11):  # stuck to the jaws while the centroid drops 1 mm
        meter.update(_result(k * DT, [0.05, 0.05, -1.0, -1.0], on, drop=1e-4 * k,
                             dimension=dimension))
    assert meter.largest == 0.0 and meter.centroid_drop == pytest.approx(1e-3)
    for k in range(11, 21):  # both slide 10 mm/s down the jaws for 0.1 s: 1 mm
        meter.update(_result(k * DT, [0.04, 0.04, 0.0, 0.0], on, dimension=dimension))
    assert meter.largest == pytest.approx(1e-3)
    for k in range(21, 41):  # pushed back up 2 mm: the slide stops at 0, its largest stays
        meter.update(_result(k * DT, [0.06, 0.06, 0.0, 0.0], on, dimension=dimension))
    assert meter.slide == 0.0 and meter.largest == pytest.approx(1e-3)
    assert meter.centroid_drop == pytest.approx(1e-3)


def test_steps_outside_the_sliding_phases_only_move_the_time_on():
    meter = ContactSlide(0.0)
    meter.update(_result(0.5, [-1.0], [0], drop=0.02), sliding=False)
    assert meter.state() == (0.0, 0.0, 0.0) and meter.previous_time == 0.5
    meter.update(_result(0.51, [0.04], [1]))  # one step of 10 mm/s: 0.1 mm, not 5.1
    assert meter.largest == pytest.approx(1e-4)
    meter.include(Skipped(peaks=(), slide=(2e-4, 3e-4, 4e-4), previous_time=0.7))
    assert meter.state() == (2e-4, 3e-4, 4e-4) and meter.previous_time == 0.7
    meter.include(Skipped(peaks=(), slide=(0.0, 0.0, 0.0), previous_time=0.9), sliding=False)
    assert meter.state() == (2e-4, 3e-4, 4e-4) and meter.previous_time == 0.9


def _same_motion(force: float, lift: float, overrides=()):
    """A pick (lift ``lift`` m, hold ``SETTLE_TIME``) and a pick-and-place scenario cut
    to the same motion (no approach, the same close and lift speeds, squeeze and hold
    ``SETTLE_TIME``, ended after the hold): (scenario evaluation, pick evaluation)."""
    config = load_config(overrides=list(overrides))
    scenario = load_scenario('pick_and_place').with_values(
        approach__height=0.0, close__force=force, close__speed=config['gripper.close_speed'],
        squeeze__time=SETTLE_TIME, lift__height=lift, lift__speed=config['gripper.lift_speed'])
    runs = []
    for machine in (lambda sim: PickAndPlace(sim, scenario, until='lift'),
                    lambda sim: GraspSequence(sim, force, lift_height=lift,
                                              hold_time=SETTLE_TIME)):
        sim = make_simulation(scenario_config(scenario, overrides=list(overrides)))
        runs.append(evaluate(sim, machine(sim), force))
    return runs


@pytest.mark.parametrize('force', [3.0, 50.0])
def test_pick_and_run_measure_the_same_slide_on_the_same_motion(force):
    """In 2D the two machines take the same steps: the same slide and centroid drop to
    the last bit. At 50 N the centroid drops 0.9 mm as the squeezed fruit relaxes, 20
    times what its contacts slide: the pick measured that drop as its slip."""
    run, pick = _same_motion(force, 0.03)
    assert run.steps == pick.steps
    for key in ('slip_distance', 'centroid_drop'):
        assert pick.summary[key] == run.summary[key], key
    assert pick.slip_distance == run.slip_distance < 0.1 * SLIP_TOLERANCE
    assert pick.slipped is run.slipped is False
    if force > 10:
        assert pick.summary['centroid_drop'] > 10 * pick.slip_distance


def test_pick_and_run_measure_the_same_slide_in_3d():
    """3D (the last coordinate is the height): the scenario's approach centres the jaws
    on the fruit first, two steps, so the slides agree to 1 %, not to the bit."""
    coarse = ['dimension=3', 'fruit.mesh.subdivisions=3']
    run, pick = _same_motion(3.0, 0.01, coarse)
    assert abs(run.steps - pick.steps) <= 3
    for key in ('slip_distance', 'centroid_drop'):
        assert pick.summary[key] == pytest.approx(run.summary[key], rel=0.01), key
    assert pick.summary['centroid_drop'] > 2 * pick.slip_distance


def test_pick_prints_its_slide_and_its_centroid_drop_apart(capsys):
    argv = ['pick', '--force', '50', '--lift', '0.03', '--hold', '0.2']
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].strip().startswith('the fruit was held')  # (and bruised)
    slide = [line for line in lines if line.strip().startswith('slip in the jaws')]
    drop = [line for line in lines if line.strip().startswith('centroid drop')]
    assert len(slide) == len(drop) == 1
    assert float(slide[0].split()[4]) < 0.1 and float(drop[0].split()[2]) > 0.5
    assert main([*argv, '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['outcome'] == 'held' and not data['summary']['slipped']
    assert data['slip_distance'] == data['summary']['slip_distance'] < 1e-4
    assert data['summary']['centroid_drop'] > 5e-4
