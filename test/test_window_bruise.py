"""The bruise estimates agree with what the simulation finds, contact by contact: with a
soft pad the jaw contact is spared (its Hertz estimate is far above the flat finger's)
and the fruit, squeezed on the table, bruises at the table once the table carries its
own Hertz bruise load."""
import math

import pytest

from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import evaluate
from gripper_sim.workflows.scenario import PickAndPlace, load_scenario, scenario_config
from gripper_sim.workflows.window import (OUT_OF_REACH, GraspWindow, Trial, _ask,
                                          estimates, hold_verdict, lower_bound_limited_by,
                                          reach_bracket, run_search, run_trial,
                                          table_bruise_load, trial_of, trial_setup,
                                          upper_bound_limited_by, window_bisections)


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


def _trial(force, kind, outcome, bruised, peak=None):
    return Trial(force=force, kind=kind, held=False, slipped=True, bruised=bruised,
                 outcome=outcome, slip_distance=0.0,
                 peak_grip_force=force if peak is None else peak,
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


def test_a_grip_the_fingers_do_not_reach_ends_the_safe_side():
    """A 'bruise' trial whose grip stays below its command, undamaged (a 3D Fin Ray
    buckles at about 76 N of grip, README), reads 'not reached' and is not safe: the
    window's upper bound is the largest force reached, limited by 'grip not reached',
    not inf. A run that ended 'failed' with its grip reached (the fruit not placed) and
    an undamaged one that held are safe."""
    buckles_at, bruise_above = 76.0, 150.0

    def trial(request):
        kind, force = request
        reached = force <= buckles_at
        return _trial(force, kind, 'held' if reached else 'failed', force > bruise_above
                      and reached, peak=force if reached else buckles_at)

    config = {'gripper.max_force': 200.0, 'gripper.finger.pad.enabled': False,
              'contact.jaw.static_friction': 0.5, 'contact.jaw.kinetic_friction': 0.4,
              'dimension': 3}
    bruise = window_bisections(config, 2.0, 20.0, tolerance=0.03)[1]
    asked = []
    max_force = run_search(_ask(bruise), lambda r: asked.append(trial(r)) or asked[-1])
    # a grip within 3 % of its command counts as reached (the scenario's FORCE_REACHED)
    assert 0.97 * buckles_at < max_force <= buckles_at / 0.97
    assert upper_bound_limited_by(max_force, asked) == 'grip not reached'
    above = min((t for t in asked if t.force > max_force), key=lambda t: t.force)
    assert above.verdict == 'not reached' and not above.safe and not above.bruised
    assert _trial(90.0, 'bruise', 'failed', False, peak=89.0).safe  # reached: 0.97
    assert _trial(90.0, 'bruise', 'held', False, peak=60.0).safe  # held: no 'failed'
    window = GraspWindow(fruit='apple', finger='fin_ray', min_force=2.0,
                         max_force=max_force, min_estimate=1.0, max_estimate=16.0,
                         mass=0.134, friction=0.5, tolerance=0.03, trials=asked)
    assert window.as_dict()['max_force_limited_by'] == 'grip not reached'


def hold_search(hold_from: float, reach: float, limit: float = 200.0):
    """The window's hold search (its bisection and verdict) against trials that hold
    from ``hold_from`` N, where the fingers deliver at most ``reach`` N; (answer, trials
    in the order asked)."""
    def trial(request):
        kind, force = request
        reached = force <= reach
        held = reached and force >= hold_from
        result = _trial(force, kind, 'held' if held else 'failed' if not reached
                        else 'dropped', False, peak=force if reached else reach)
        result.held = held
        return result

    config = {'gripper.max_force': limit, 'gripper.finger.pad.enabled': False,
              'contact.jaw.static_friction': 0.5, 'contact.jaw.kinetic_friction': 0.4,
              'dimension': 2}
    hold = window_bisections(config, 2.0, 20.0, tolerance=0.03)[0]
    asked = []
    answer = run_search(_ask(hold), lambda r: asked.append(trial(r)) or asked[-1])
    return answer, asked


def test_a_grip_the_fingers_do_not_reach_stops_the_hold_search_climbing():
    """A 'hold' trial whose grip is not reached reads 'not reached' (``OUT_OF_REACH`` to
    the search): no larger force is tried, the search looks below it for a force that
    holds, and where none does it stops within the tolerance, 'grip not reached',
    instead of doubling up to gripper.max_force."""
    # the hold lies below the reach: found as without one (the bracket's upper end, 2.9 N,
    # or the doubling's 11.5 N out of reach)
    for hold_from, reach in ((2.5, 2.7), (5.9, 6.5)):
        answer, asked = hold_search(hold_from, reach)
        assert hold_from <= answer <= hold_from / 0.97
        assert max(t.force for t in asked) < 2 * reach
        assert lower_bound_limited_by(answer, asked) is None
        unreached = [t for t in asked if not t.reached]
        assert unreached and all(t.verdict == 'not reached'
                                 and hold_verdict(t) == OUT_OF_REACH for t in unreached)
    # nothing holds below the reach: none, bracketed to the tolerance, nothing above tried
    answer, asked = hold_search(hold_from=5.0, reach=4.0)
    assert answer is None and lower_bound_limited_by(answer, asked) == 'grip not reached'
    slid, first_unreached = reach_bracket(asked)
    # (a grip within 3 % of its command counts as reached)
    assert slid.force <= 4.0 / 0.97 < first_unreached.force / 0.97
    assert first_unreached.force - slid.force <= 0.03 * first_unreached.force
    assert max(t.force for t in asked) < 2 * 4.0 and len(asked) < 12
    # not even the first force is reached: the search halves down below it
    answer, asked = hold_search(hold_from=1.2, reach=0.9)
    assert answer is None and lower_bound_limited_by(answer, asked) == 'grip not reached'
    assert reach_bracket(asked)[0].force <= 0.9 / 0.97 < reach_bracket(asked)[1].force / 0.97
    # the fingers deliver every force: none up to the limit, as before
    answer, asked = hold_search(hold_from=300.0, reach=math.inf)
    assert answer is None and lower_bound_limited_by(answer, asked) == 'gripper.max_force'
    assert max(t.force for t in asked) == 200.0
    # ... unless the trial at the limit did not converge: whether it holds is not known
    failed = [t if t.force < 200.0 else _trial(200.0, 'hold', 'solver failed', False)
              for t in asked]
    assert lower_bound_limited_by(None, failed) == 'solver failure'


def test_a_hold_at_every_force_tried_down_to_the_last_widening_answers_a_force_tried():
    """Held at every force down to the bracket's last halving: the answer is the smallest
    force tried (its trial measured), not the half below it, never tried."""
    answer, asked = hold_search(hold_from=1e-6, reach=math.inf)
    held = [t.force for t in asked if t.held]
    assert len(asked) == 8 and len(held) == 8 and answer == min(held)


def test_the_window_command_says_when_the_grip_was_not_reached(monkeypatch, capsys):
    """`gripper-sim window`'s text for a window that ends below a trial whose grip was
    not reached: the bound as 'not found: safe up to', and the trial's peak grip."""
    from gripper_sim.cli.main import main
    from gripper_sim.workflows import window as window_module
    trials = [_trial(2.0, 'hold', 'dropped', False), _trial(2.05, 'hold', 'failed', False,
                                                             peak=1.96),
              _trial(70.0, 'bruise', 'held', False),
              _trial(80.0, 'bruise', 'failed', False, peak=76.4)]

    def grasp_window(config, scenario, tolerance, progress, workers=1):
        for trial in trials:
            progress(trial)
        return GraspWindow(fruit='apple', finger='fin_ray', min_force=None, max_force=70.0,
                           min_estimate=1.3, max_estimate=16.6, mass=0.134, friction=0.5,
                           tolerance=tolerance, trials=trials, max_force_measured=70.0)

    monkeypatch.setattr(window_module, 'grasp_window', grasp_window)
    assert main(['window', '--fruit', 'apple', '--finger', 'fin_ray']) == 0
    out = capsys.readouterr().out
    assert 'hold   trial    2.050 N: not reached' in out
    assert 'bruise trial   80.000 N: not reached' in out
    assert ('holds from      not found: slides at 2 N, does not reach a grip of 2.05 N '
            '(peak 1.96 N): the fingers deliver no more') in out
    assert 'bruises above   not found: safe up to 70 N commanded' in out
    assert 'the nearest trial above, 80 N, did not reach its grip: peak 76.4 N' in out


def test_a_silicone_fin_ray_does_not_reach_a_firm_grip():
    """A real case: the Fin Ray in silicone (Dragon Skin 30, E = 0.59 MPa) gives way;
    a 'bruise' trial at 10 N closes the jaws to their stop with about 2.6 N of grip
    (`gripper-sim window ... --set gripper.finger.fin_ray.material=silicone`: safe up to
    2.59 N, grip not reached above, README), the apple undamaged: 'not reached', not
    'safe'."""
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, finger='fin_ray',
                             overrides=['gripper.finger.fin_ray.material=silicone'])
    trial = run_trial(config, scenario, ('bruise', 10.0))
    assert trial.outcome == 'failed' and not trial.bruised
    assert 1.0 < trial.peak_grip_force < 0.5 * 10.0
    assert trial.verdict == 'not reached' and not trial.safe
    # its hold trial at 10 N likewise: the hold search climbs no higher
    trial = run_trial(config, scenario, ('hold', 10.0))
    assert trial.outcome == 'failed' and not trial.held
    assert trial.verdict == 'not reached' and hold_verdict(trial) == OUT_OF_REACH


def test_the_window_command_says_when_no_hold_is_known_for_a_solver_failure(monkeypatch,
                                                                           capsys):
    """A hold search whose trial at gripper.max_force did not converge: not 'none up to
    gripper.max_force' but that whether it holds there is not known."""
    from gripper_sim.cli.main import main
    from gripper_sim.workflows import window as window_module
    trials = [_trial(100.0, 'hold', 'dropped', False),
              _trial(200.0, 'hold', 'solver failed', False),
              _trial(10.0, 'bruise', 'held', False), _trial(20.0, 'bruise', 'bruised', True)]

    def grasp_window(config, scenario, tolerance, progress, workers=1):
        return GraspWindow(fruit='apple', finger='flat', min_force=None, max_force=10.0,
                           min_estimate=1.3, max_estimate=16.6, mass=0.134, friction=0.5,
                           tolerance=tolerance, trials=trials, max_force_measured=10.0)

    monkeypatch.setattr(window_module, 'grasp_window', grasp_window)
    assert main(['window', '--fruit', 'apple', '--quiet']) == 0
    out = capsys.readouterr().out
    assert ('holds from      not found up to gripper.max_force (200 N): the trial there did '
            'not converge') in out
