"""The grasp window on several processes (``workflows.speculative``): the same trials, in
the same order, and the same window as one process, whatever order the trials finish in."""
import json
import math

import pytest

from gripper_sim.errors import GripperSimError
from gripper_sim.workflows.speculative import Search, run_searches
from gripper_sim.workflows.window import (OUT_OF_REACH, _ask, bisection, grasp_window,
                                          hold_verdict, run_search)
from gripper_sim.workflows.scenario import load_scenario, scenario_config

from test_cli_offline import gripper_sim


class FakeTrial:
    """A trial of the synthetic searches: its force and the verdicts (the fingers deliver
    at most ``reach`` N: above it a grip is not reached and nothing holds)."""

    def __init__(self, kind, force, hold_from, bruise_above, reach=math.inf):
        self.kind, self.force = kind, force
        self.reached = force <= reach
        self.held = hold_from <= force <= reach
        self.bruised = force > bruise_above


class LastFirstPool:
    """Runs each started trial at once but hands the results back last-started first,
    so that trials finish out of the order they were asked in; records what ran."""

    def __init__(self, hold_from, bruise_above, fail_at=(), reach=math.inf):
        self.hold_from, self.bruise_above, self.fail_at = hold_from, bruise_above, fail_at
        self.reach = reach
        self.waiting, self.started, self.most_running = [], [], 0

    def start(self, request):
        kind, force = request
        self.started.append(request)
        outcome = (GripperSimError(f'failed at {force}') if
                   any(math.isclose(force, f) for f in self.fail_at)
                   else FakeTrial(kind, force, self.hold_from, self.bruise_above,
                                  self.reach))
        self.waiting.append((request, outcome))
        self.most_running = max(self.most_running, len(self.waiting))

    def finished(self):
        return self.waiting.pop()


def searches(limit=200.0, tolerance=0.03):
    return [Search('hold', lambda: bisection(1.0, 1.5, limit, tolerance, want_smallest=True),
                   hold_verdict, (True, False, OUT_OF_REACH)),
            Search('bruise', lambda: bisection(8.0, 12.0, limit, tolerance,
                                               want_smallest=False),
                   lambda trial: not trial.bruised)]


def serial(hold_from, bruise_above, limit=200.0, reach=math.inf):
    """The searches one after the other in this process: (answers, trials in order)."""
    trials, cache = [], {}

    def trial(request):
        kind, force = request
        key = (kind, round(force, 12))
        if key not in cache:
            cache[key] = FakeTrial(kind, force, hold_from, bruise_above, reach)
            trials.append(cache[key])
        return cache[key]

    def both():
        hold, bruise = searches(limit)
        return (yield from _ask(hold)), (yield from _ask(bruise))
    return list(run_search(both(), trial)), trials


@pytest.mark.parametrize('hold_from,bruise_above,reach', [
    (2.7, 31.0, math.inf),   # both brackets widen upwards
    (0.2, 3.0, math.inf),    # the hold bracket widens down; the bruise one down too
    (5.0, 250.0, math.inf),  # nothing bruises up to the limit: inf
    (300.0, 0.01, math.inf),  # nothing holds up to the limit, everything bruises
    (2.7, 31.0, 4.0),        # the climb overshoots the reach, then finds the hold below
    (5.0, 31.0, 4.0),        # nothing holds below the reach
    (2.7, 31.0, 0.6),        # not even the first force is reached
])
@pytest.mark.parametrize('workers', [1, 2, 3, 5])
def test_parallel_searches_ask_and_answer_as_the_serial_ones(hold_from, bruise_above,
                                                             reach, workers):
    answers, trials = serial(hold_from, bruise_above, reach=reach)
    pool = LastFirstPool(hold_from, bruise_above, reach=reach)
    reported = []
    run = run_searches(searches(), pool, workers, reported.append)
    assert run.answers == answers
    parallel = run.paths[0] + run.paths[1]
    assert [(t.kind, t.force) for t in parallel] == [(t.kind, t.force) for t in trials]
    # progress sees each search's trials in its own order, each once
    for kind in ('hold', 'bruise'):
        assert ([t.force for t in reported if t.kind == kind]
                == [t.force for t in trials if t.kind == kind])
    assert len(reported) == len(trials)
    assert pool.most_running <= workers
    assert run.wasted == len(set(pool.started)) - len(trials)
    if workers >= 3:  # the spare processes look ahead
        assert pool.most_running == workers


def test_a_failed_trial_on_the_path_stops_the_run_and_one_off_it_does_not():
    answers, trials = serial(2.7, 31.0)
    hold_path = [t.force for t in trials if t.kind == 'hold']
    with pytest.raises(GripperSimError, match='failed at'):
        run_searches(searches(), LastFirstPool(2.7, 31.0, fail_at=hold_path[2:3]), 1)
    # a look-ahead the search did not take failed: the run goes on as the serial one
    pool = LastFirstPool(2.7, 31.0)
    run_searches(searches(), pool, 5)
    off_path = [f for kind, f in pool.started if kind == 'hold' and f not in hold_path]
    assert off_path
    run = run_searches(searches(), LastFirstPool(2.7, 31.0, fail_at=off_path), 5)
    assert run.answers == answers


def test_workers_must_be_a_whole_number_of_at_least_one():
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, fruit=None, finger=None, config_file=None,
                             overrides=[])
    for bad in (0, -1, 1.5, True):
        with pytest.raises(GripperSimError, match='workers'):
            grasp_window(config, scenario, 0.25, workers=bad)


def test_window_on_two_processes_is_the_serial_window():
    """The default apple's window (coarse tolerance) on one and on two worker processes
    (spawned: the trials run in other interpreters): every trial and bound to the bit."""
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, fruit=None, finger=None, config_file=None,
                             overrides=[])
    one = grasp_window(config, scenario, 0.25)
    two = grasp_window(config, scenario, 0.25, workers=2)
    assert two.workers == 2 and one.workers == 1
    assert two.answer_dict() == one.answer_dict()
    assert len(one.trials) >= 5 and one.exists


def test_cli_window_with_workers_reports_them():
    run = gripper_sim('window', '--tolerance', '0.25', '--workers', '2', '--json',
                      timeout=600)
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data['workers'] == 2 and data['window']
    assert data['look_ahead_trials'] >= 0
    assert [t['kind'] for t in data['trials']][:1] == ['hold']
