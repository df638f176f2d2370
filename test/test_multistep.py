"""The compiled multi-step advance (``core.multistep``, ``core.advance_kernels``) against
the per-step route: the same grasp, step for step.

A run that nobody watches (``evaluate`` or ``run_scenario`` without ``on_step``) runs the
steps at which its machine decides nothing in compiled calls; a watched run steps one by
one (``Simulation.step``). Both must end in the same state (positions within 1e-9 m),
with the same outcome, steps, gap solves and peaks.
"""
import math

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.measures import numpy_sum
from gripper_sim.core.multistep import StopRules
from gripper_sim.core.simulation import Simulation
from gripper_sim.workflows.grasp import GraspSequence, evaluate
from gripper_sim.workflows.scenario import load_scenario, run_scenario, scenario_config

SET_UPS = {
    'shell': ['fruit.model=shell'],
    'shell-arc': ['fruit.model=shell', 'gripper.finger.type=arc'],
    'shell-vgroove': ['fruit.model=shell', 'gripper.finger.type=vgroove'],
    'shell-pad': ['fruit.model=shell', 'gripper.finger.pad.enabled=true'],
    'solid': ['fruit.model=solid'],
    'solid-vgroove': ['fruit.model=solid', 'gripper.finger.type=vgroove'],
    'solid-pad': ['fruit.model=solid', 'gripper.finger.pad.enabled=true'],
}


def _grasp(overrides, watched, force=3.0):
    """(simulation, evaluation, sim.step calls) of a grasp-and-lift, watched or not."""
    sim = Simulation(load_config(overrides=overrides))
    calls = [0]
    step = sim.step

    def counted():
        calls[0] += 1
        return step()

    sim.step = counted
    sequence = GraspSequence(sim, force, lift_height=0.02, hold_time=0.1)
    evaluation = evaluate(sim, sequence, force,
                          on_step=(lambda _result, _phase: None) if watched else None)
    return sim, evaluation, calls[0]


def _same_end(watched, unwatched):
    (a, ea, _), (b, eb, _) = watched, unwatched
    assert ea.outcome == eb.outcome
    assert ea.steps == eb.steps and a._step == b._step
    assert a.gap_solves == b.gap_solves
    assert a.newton_iterations == b.newton_iterations
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.v, a.v, rtol=0, atol=1e-6)
    assert b.gripper_state.gap == pytest.approx(a.gripper_state.gap, abs=1e-12)
    row_a, row_b = ea.row(), eb.row()
    for key, value in row_a.items():
        if isinstance(value, float):
            assert row_b[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
        else:
            assert row_b[key] == value, key


@pytest.mark.parametrize('name', list(SET_UPS))
def test_an_unwatched_grasp_runs_in_compiled_calls_and_ends_as_a_watched_one(name):
    watched = _grasp(SET_UPS[name], watched=True)
    unwatched = _grasp(SET_UPS[name], watched=False)
    _same_end(watched, unwatched)
    assert watched[1].outcome == 'held'
    steps = watched[1].steps
    assert watched[2] == steps
    # closing, squeezing, lifting, holding: a call per phase (and a few per-step ones)
    assert unwatched[2] < 20 < steps


def test_a_bruising_grasp_stops_where_the_bruise_starts():
    # a low bruise pressure: the fruit bruises on the table before the grip (bruised_at
    # comes from the first bruised step)
    overrides = ['fruit.model=shell', 'fruit.bruise_pressure=2e4']
    watched = _grasp(overrides, watched=True)
    unwatched = _grasp(overrides, watched=False)
    _same_end(watched, unwatched)
    assert watched[1].bruised and watched[1].bruised_at in ('jaws', 'table')


def test_steps_the_kernel_halves_go_to_the_per_step_route():
    # two Newton iterations: some steps fail and are halved by Simulation.step, and the
    # grasp ends in a solver failure at the same step on both routes
    overrides = ['fruit.model=shell', 'sim.max_newton_iterations=2']
    watched = _grasp(overrides, watched=True)
    unwatched = _grasp(overrides, watched=False)
    _same_end(watched, unwatched)


def test_an_observer_keeps_every_step_on_the_per_step_route():
    sim = Simulation(load_config(overrides=['fruit.model=shell']))
    seen = []
    sim.add_observer(seen.append)
    sim.command_force(3.0)
    assert sim.advance(StopRules(max_steps=5)) is None
    sim._observers.clear()
    result, skipped = sim.advance(StopRules(max_steps=5))
    assert sim._step == 5 and result.step == 5
    assert skipped.peaks[0] >= result.grip_force  # the peaks include the last step


def test_max_steps_and_time_limits_stop_an_advance():
    sim = Simulation(load_config(overrides=['fruit.model=shell']))
    sim.command_force(3.0)
    result, _ = sim.advance(StopRules(max_steps=7))
    assert sim._step == 7 and result.step == 7
    result, _ = sim.advance(StopRules(end=sim.time + 3.5 * sim.dt))
    assert sim._step == 11 and result.time >= 10.5 * sim.dt


@pytest.mark.parametrize('options', [{}, {'stop_on_slip': True, 'stop_on_bruise': True}])
def test_a_pick_and_place_ends_the_same_unwatched(options):
    scenario = load_scenario('pick_and_place')
    ends = []
    for watched in (True, False):
        sim = Simulation(scenario_config(scenario))
        summary = run_scenario(sim, scenario, on_step=(lambda _r, _p: None) if watched
                               else None, **options)
        ends.append((sim, summary))
    (a, sa), (b, sb) = ends
    assert a._step == b._step
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-9)
    for key, value in sa.items():
        if isinstance(value, float):
            assert sb[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
        else:
            assert sb[key] == value, key


@pytest.mark.parametrize('count', [0, 1, 7, 8, 9, 16, 17, 63, 128, 129, 300])
def test_the_advances_sum_adds_as_numpy_does(count):
    values = np.random.default_rng(count).normal(size=max(count, 1)) * 1e-3
    expected = float(np.add.reduce(values[:count])) if count else 0.0
    assert numpy_sum(values, count) == expected
    if count:
        assert numpy_sum(values, count) / count == float(np.mean(values[:count]))
    assert math.isfinite(numpy_sum(values, count))
