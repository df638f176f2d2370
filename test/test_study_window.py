"""The population window: zero spread gives `window`'s answer; the statistics on
windows whose answer is known."""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from gripper_sim.workflows.population_window import SampleWindow, population_window
from gripper_sim.workflows.study import run_study
from gripper_sim.workflows.study_report import write_report
from gripper_sim.workflows.study_spec import load_study
from gripper_sim.workflows.window import grasp_window
from chromium import Browser
from test_analysis_html import open_report
from test_study_dask import STUDY


def zero_spread_study() -> str:
    """The small study of the Dask tests, its fruits all the same (zero spread)."""
    data = yaml.safe_load(STUDY)
    data.update(name='zero', window={'tolerance': 0.05})
    data.pop('axes')
    data['population'] = {'samples': 3, 'seed': 1, 'distributions': {
        'fruit.shape.diameter': {'distribution': 'normal', 'mean': 0.0635, 'std': 0.0},
        'fruit.density': {'distribution': 'list', 'values': [1000.0]}}}
    return yaml.safe_dump(data)


def test_a_zero_spread_population_has_the_window_of_its_single_fruit(tmp_path):
    path = tmp_path / 'zero.yaml'
    path.write_text(zero_spread_study())
    study = load_study(path)
    run = run_study(study, tmp_path / 'out', workers=1, progress=False)
    (point,) = run.summary['points']
    window = point['population']['window']
    assert window is not None
    # the single fruit, by the `window` command's own function
    setup = study.trial(study.points[0], 0, {})
    config = dict(setup.config)
    config['gripper.initial_lift'] += study.base['scenario']['approach.height']
    single = grasp_window(config, study.base['scenario'], tolerance=study.tolerance)
    assert single.exists
    assert window['low'] == pytest.approx(single.min_force, rel=study.tolerance)
    assert window['high'] == pytest.approx(single.max_force, rel=study.tolerance)
    samples = point['samples']
    assert len(samples) == 3 and all(s == {**samples[0], 'sample': s['sample']}
                                     for s in samples)
    # identical fruits are one case: each force was computed once
    assert run.computed == len(single.trials)
    # the study's report opens offline in a browser, its plots drawn, no console error
    write_report(run.summary, run.rows, tmp_path / 'out')
    with Browser() as browser:
        assert open_report(browser, tmp_path / 'out' / 'report.html',
                           tmp_path / 'report.png') >= 1
        text = browser.evaluate('document.body.textContent')
    assert 'study zero' in text and 'success probability vs grip force' in text


def windows_from(lows, highs):
    return [SampleWindow(i, lo, hi) for i, (lo, hi) in enumerate(zip(lows, highs))]


def test_the_window_is_where_the_fraction_of_fruits_succeeds():
    lows = np.linspace(1.0, 2.0, 100)  # fruit i holds from 1 + i/99 N
    highs = np.linspace(10.0, 20.0, 100)  # and bruises above 10 + 10 i/99 N
    result = population_window(windows_from(lows, highs), 200.0, 0.99, 0.95, seed=3)
    # 99 of 100 succeed from the 99th-smallest minimum to the 2nd-smallest maximum
    assert result['window']['low'] == pytest.approx(lows[98])
    assert result['window']['high'] == pytest.approx(highs[1])
    ci = result['ci']
    assert ci['low'][0] <= lows[98] <= ci['low'][1] <= lows[99]
    assert highs[0] <= ci['high'][0] <= highs[1] <= ci['high'][1]
    # 100 fruits cannot show 99 % at 95 % confidence: 299 are needed
    assert result['confident_window'] is None and result['samples_needed'] == 299
    curve = result['curve']
    at = {f: p for f, p in zip(curve['force'], curve['p'])}
    assert at[lows[98]] == pytest.approx(0.99) and max(curve['p']) == 1.0
    assert all(lo <= p <= hi for p, lo, hi in zip(curve['p'], curve['lower'],
                                                  curve['upper']))


def test_no_safe_force_and_a_confident_window():
    # half the fruits bruise below the force that holds the other half
    lows = [1.0] * 50 + [5.0] * 50
    highs = [4.0] * 50 + [9.0] * 50
    none = population_window(windows_from(lows, highs), 200.0, 0.99, 0.95)
    assert none['window'] is None and none['no_window_share'] == 1.0
    assert max(none['curve']['p']) == pytest.approx(0.5)
    # 400 identical fruits, undamaged up to the gripper's limit: a confident window
    many = population_window(windows_from([2.0] * 400, [math.inf] * 400), 50.0, 0.99, 0.95)
    assert many['window'] == dict(low=2.0, high=50.0, high_is_limit=True)
    assert many['confident_window'] == dict(low=2.0, high=50.0)
    # a fruit that nothing holds counts against every force
    some = windows_from([2.0] * 99 + [None], [8.0] * 100)
    result = population_window(some, 50.0, 0.99, 0.95)
    assert result['window']['low'] == 2.0 and result['holds_nowhere'] == 1
    assert population_window(some, 50.0, 0.995, 0.95)['window'] is None


def test_a_force_grid_evaluates_every_fruit_at_every_force(tmp_path):
    data = yaml.safe_load(STUDY)
    data['axes'] = {'force': [0.5, 3.0, 60.0]}
    data['population']['samples'] = 2
    path = tmp_path / 'grid.yaml'
    path.write_text(yaml.safe_dump(data))
    study = load_study(path)
    assert study.method == 'grid'
    run = run_study(study, tmp_path / 'out', workers=1, progress=False)
    assert run.computed == 6 and len(run.rows) == 6
    assert {(r['sample'], r['force'], r['kind']) for r in run.rows} == {
        (s, f, 'hold') for s in (0, 1) for f in (0.5, 3.0, 60.0)}
    outcome = {(r['sample'], r['force']): r['outcome'] for r in run.rows}
    assert all(outcome[(s, 0.5)] == 'dropped' for s in (0, 1))  # below m g / (2 mu)
    assert all(outcome[(s, 3.0)] == 'held' for s in (0, 1))
    assert all(outcome[(s, 60.0)] in ('bruised', 'crushed') for s in (0, 1))
    (point,) = run.summary['points']
    assert point['population']['curve']['p'] == [0.0, 1.0, 0.0]
    assert point['population']['window'] == dict(low=3.0, high=3.0, high_is_limit=False)


def test_the_population_counts_the_upper_bounds_a_solver_failure_set():
    """A fruit whose upper bound is where its solver stopped (not a bruise) is counted,
    and the study's line says so."""
    from gripper_sim.cli.study import describe_window
    windows = [SampleWindow(i, 2.0, 20.0 + i, 'solver failure' if i < 3 else 'bruise')
               for i in range(10)]
    result = population_window(windows, 200.0, 0.9, 0.95)
    assert result['solver_failure_bounds'] == 3
    assert '3 fruits\' upper bounds are solver failures' in describe_window(result, '90 %')
    plain = population_window(windows_from([2.0] * 10, [20.0] * 10), 200.0, 0.9, 0.95)
    assert plain['solver_failure_bounds'] == 0
    assert 'solver' not in describe_window(plain, '90 %')


def test_a_grid_study_tells_a_solver_failure_above_the_safe_forces_from_a_bruise():
    """A study over a list of forces: a fruit's window ends at its largest safe force;
    the force above it failed to converge for one fruit and bruised the other."""
    from types import SimpleNamespace
    from gripper_sim.workflows.study import _sample_windows

    def evaluation(force, outcome):
        bad = outcome in ('bruised', 'solver failed')
        return SimpleNamespace(force=force, outcome=outcome, held=not bad, bruised=bad,
                               crushed=outcome == 'solver failed', slip_distance=0.0,
                               peak_grip_force=force, peak_jaw_pressure=0.0,
                               peak_table_pressure=0.0, peak_damage_pressure=0.0,
                               bruised_at='')

    def chain(sample, last):
        return SimpleNamespace(done=True, setup=SimpleNamespace(sample=sample), result=[
            evaluation(5.0, 'held'), evaluation(10.0, 'held'), evaluation(20.0, last)])

    windows = _sample_windows(SimpleNamespace(forces=(5.0, 10.0, 20.0)),
                              [chain(0, 'solver failed'), chain(1, 'bruised')])
    assert [(w.min_force, w.max_force) for w in windows] == [(5.0, 10.0), (5.0, 10.0)]
    assert [w.max_force_limited_by for w in windows] == ['solver failure', 'bruise']


def evaluation(force: float, outcome: str, peak: float):
    """An undamaged grasp evaluation of a force grid (the fields ``_sample_windows``
    reads): its force and outcome, held when 'held', its peak grip force ``peak`` N."""
    from types import SimpleNamespace
    return SimpleNamespace(force=force, outcome=outcome, held=outcome == 'held',
                           bruised=False, crushed=False, slip_distance=0.0,
                           peak_grip_force=peak, peak_jaw_pressure=0.0,
                           peak_table_pressure=0.0, peak_damage_pressure=0.0, bruised_at='')


def test_a_force_grid_whose_largest_force_is_not_reached_ends_below_it():
    """On a force grid an undamaged run whose grip stayed below its command (outcome
    'failed') is not safe: the fruit's upper bound is the force below it, limited by
    'grip not reached', and the population counts such fruits."""
    from types import SimpleNamespace
    from gripper_sim.cli.study import describe_window
    from gripper_sim.workflows.study import _sample_windows

    chain = SimpleNamespace(done=True, setup=SimpleNamespace(sample=0), result=[
        evaluation(5.0, 'held', 5.0), evaluation(10.0, 'held', 10.0),
        evaluation(20.0, 'failed', 14.0)])
    windows = _sample_windows(SimpleNamespace(forces=(5.0, 10.0, 20.0)), [chain])
    assert [(w.min_force, w.max_force, w.max_force_limited_by) for w in windows] == [
        (5.0, 10.0, 'grip not reached')]
    result = population_window(windows, limit=20.0, fraction=0.9, confidence=0.9)
    assert result['grip_limit_bounds'] == 1 and result['solver_failure_bounds'] == 0
    assert "1 fruits' upper bounds are the most grip" in describe_window(result, '90 %')


def test_a_fruit_held_by_no_grip_its_fingers_reach_is_counted():
    """On a force grid, a fruit that slid at every force its fingers reached and whose
    larger forces were not reached holds nowhere 'grip not reached'; the population
    and the study line count it apart from fruits that held at no force up to the
    limit."""
    from types import SimpleNamespace
    from gripper_sim.cli.study import describe_window
    from gripper_sim.workflows.study import _sample_windows

    unreached = SimpleNamespace(done=True, setup=SimpleNamespace(sample=0), result=[
        evaluation(2.0, 'dropped', 2.0), evaluation(4.0, 'failed', 2.6),
        evaluation(8.0, 'failed', 2.6)])
    slides = SimpleNamespace(done=True, setup=SimpleNamespace(sample=1), result=[
        evaluation(2.0, 'dropped', 2.0), evaluation(4.0, 'dropped', 4.0),
        evaluation(8.0, 'dropped', 8.0)])
    windows = _sample_windows(SimpleNamespace(forces=(2.0, 4.0, 8.0)), [unreached, slides])
    assert [(w.min_force, w.min_force_limited_by) for w in windows] == [
        (None, 'grip not reached'), (None, 'gripper.max_force')]
    result = population_window(windows, limit=8.0, fraction=0.9, confidence=0.9)
    assert result['holds_nowhere'] == 2 and result['grip_limit_holds_nowhere'] == 1
    # no fruit has a window: the success curve (0 everywhere) still spans the forces of
    # the fruits' own bounds (fruit 0 safe up to 2 N), not only the gripper's limit
    curve = result['curve']
    assert curve['force'][0] == pytest.approx(1.0) and curve['force'][-1] == pytest.approx(4.0)
    assert max(curve['p']) == 0.0
    # a fruit whose hold trial at the limit did not converge: counted apart
    failed = SampleWindow(2, None, 8.0, 'bruise', 'solver failure')
    result = population_window(windows + [failed], limit=8.0, fraction=0.9, confidence=0.9)
    assert result['holds_nowhere'] == 3 and result['solver_failure_holds_nowhere'] == 1
    assert "1 fruits held at no force below one whose trial did not converge" in (
        describe_window(result, '90 %'))
    assert '1 fruits hold at no force their fingers deliver' in describe_window(
        result, '90 %')
