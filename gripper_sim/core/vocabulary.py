"""One vocabulary for every verb: the outcome words and the JSON keys that ``squeeze``,
``pick``, ``run``, ``window``, ``analyze`` and the node's Grasp action report.

``OUTCOMES`` and ``KEYS`` are the one list: a verb reports no other word or key (a test
checks every verb's JSON against them), and the README's glossary is written from them
(``scripts/update_readme_config.py``). ``analyze`` writes the same keys with the unit as a
suffix (``peak_grip_force_n``: ``ANALYZE_UNIT_SUFFIXES``). The Grasp action's result is a
ROS interface whose fields keep their names: ``ACTION_RESULT_FIELDS`` maps them onto
these keys.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

#: slip (m) of the fruit behind the jaws beyond which it is lost, 'dropped' (e.g. the
#: jaws lifted and the fruit stayed on the table)
DROP_SLIP = 0.01


@dataclass(frozen=True)
class Term:
    """One JSON key: its unit ('' dimensionless, '-' text, flag or list) and meaning."""

    unit: str
    meaning: str


#: the outcome words, in the order of precedence of a run's one-word summary
OUTCOMES: dict[str, str] = {
    'crushed': 'the flesh failed (flesh stress above fruit.failure_stress, or the '
               'compression beyond fruit.failure_strain)',
    'dropped': 'the fruit left both jaws, or slid more than 10 mm behind them (it stayed '
               'on the table as the jaws rose), between the lift-off and the end of the hold '
               'or the transport',
    'bruised': 'the damage pressure exceeded fruit.bruise_pressure',
    'slipped': 'carried, but the fruit slid more than the slip limit in the jaws (1 mm; '
               'in the window, window.max_slip)',
    'held': 'carried to the end of the hold, sliding less than the slip limit',
    'placed': 'set down on the table at the target, clear of the jaws and at rest',
    'failed': 'the grip never reached its target, or the fruit was not placed',
    'solver failed': 'the solver did not converge (the run counts as neither held nor safe)',
    'pinched': 'the deformable fingers closed on each other over the fruit, its outline '
               'pinched between them: crushed there (bruised_at pinch), and the run ends',
    'canceled': 'the Grasp goal was canceled',
    'running': 'the run ended (time limit) before it had an outcome',
    'safe': 'a window trial that did not bruise or crush the fruit, at its commanded grip',
    'not reached': 'a window bruise trial whose grip stayed below its command, the fruit '
                   'undamaged (the fingers deliver no more): counts as neither held nor safe',
    'error': 'a study case raised an error (its message is the row\'s error)',
}

KEYS: dict[str, Term] = {
    # what ran
    'fruit': Term('-', 'fruit name (fruit.name)'),
    'finger': Term('-', 'finger name (gripper.finger.name)'),
    'model': Term('-', 'fruit model: shell, solid or point'),
    'scenario': Term('-', 'scenario name'),
    'dimension': Term('-', '2 (planar model) or 3'),
    'duration': Term('s', 'simulated time'),
    'steps': Term('-', 'time steps taken'),
    'time': Term('s', 'time series: simulation time of each step'),
    'gap': Term('m', 'time series: jaw gap'),
    'force': Term('N', 'time series: measured grip force; in the window, the commanded '
                       'force of a trial'),
    'summary': Term('-', 'the run\'s summary (the keys of this list)'),
    'phase_times': Term('s', 'start time of each phase of a scenario'),
    # outcome
    'outcome': Term('-', 'one word (see the outcome words)'),
    'success': Term('-', 'outcome is held (pick) or placed (run)'),
    'message': Term('-', 'what happened, in words'),
    'held': Term('-', 'carried to the end, slid less than the slip limit'),
    'slipped': Term('-', 'slid more than the slip limit (1 mm) in the jaws'),
    'dropped': Term('-', 'the fruit left the jaws or slid more than 10 mm behind them'),
    'dropped_at': Term('s', 'simulation time of the drop (null: not dropped)'),
    'dropped_phase': Term('-', 'phase during which it dropped'),
    'placed': Term('-', 'set down at the target (run)'),
    'sliding': Term('-', 'still sliding in the jaws at the end'),
    'bruised': Term('-', 'damage pressure above fruit.bruise_pressure'),
    'crushed': Term('-', 'the flesh failed'),
    # measures
    'slip_distance': Term('m', 'how far the fruit slid in the jaws (largest, from the '
                               'lift-off)'),
    'centroid_drop': Term('m', 'largest drop of the fruit centroid relative to the jaws '
                               '(includes its elastic sag)'),
    'peak_grip_force': Term('N', 'largest measured grip force: the mean normal force the '
                                 'fruit exerts on the two jaws'),
    'peak_compression': Term('m', 'largest loss of width along the closing axis'),
    'peak_jaw_pressure': Term('Pa', 'largest contact pressure at the jaws, from the '
                                    'model\'s node forces (2D: planar line contact; 3D: '
                                    'over the contact patch)'),
    'peak_table_pressure': Term('Pa', 'largest contact pressure on the table, measured '
                                      'as peak_jaw_pressure'),
    'peak_damage_pressure': Term('Pa', 'largest pressure of the damage model, compared '
                                       'with fruit.bruise_pressure (2D: Hertz estimate of '
                                       'each contact, jaws and table; 3D: resolved)'),
    'peak_flesh_stress': Term('Pa', 'largest flesh stress of the damage model'),
    'bruised_at': Term('-', 'where the fruit first bruised: jaws, table, or pinch (between '
                            'deformable fingers closed on each other; null, or empty in a '
                            'study\'s rows: not bruised)'),
    'bruised_length': Term('m', '2D: length of the outline bruised'),
    'bruised_fraction': Term('', 'fraction of the outline (2D) or surface (3D) bruised'),
    'final_gap': Term('m', 'jaw gap at the end'),
    'final_centroid': Term('m', 'fruit centroid at the end'),
    'peak_contact_length': Term('m', '2D: largest contact length (both jaws)'),
    'contact_length_at_peak_force': Term('m', '2D: contact length at the peak grip force'),
    'peak_contact_area': Term('m^2', '3D: largest contact area (both jaws)'),
    'contact_area_at_peak_force': Term('m^2', '3D: contact area at the peak grip force'),
    'peak_patch_radius': Term('m', '3D: largest contact patch radius (larger jaw)'),
    'patch_radius_at_peak_force': Term('m', '3D: patch radius at the peak grip force'),
    # the grasp window
    'window': Term('-', 'a force holds without bruising'),
    'min_force': Term('N', 'lower bound, commanded: the smallest force whose trial slid '
                           'less than window.max_slip'),
    'max_force': Term('N', 'upper bound, commanded: the largest force that did not bruise '
                           'and was reached '
                           '("inf": none up to gripper.max_force)'),
    'min_force_measured': Term('N', 'lower bound, measured: peak_grip_force of its trial'),
    'max_force_measured': Term('N', 'upper bound, measured: peak_grip_force of its trial '
                                    '(null when max_force is "inf")'),
    'min_force_limited_by': Term('-', "why min_force is null: 'gripper.max_force' (no "
                                      "force up to it held), 'grip not reached' (no "
                                      'force held below the smallest whose grip was not '
                                      'reached, to the tolerance: the fingers deliver no '
                                      "more) or 'solver failure' (the trial at the largest "
                                      'force did not converge); null when min_force was '
                                      'found'),
    'max_force_limited_by': Term('-', "what ended the safe side at max_force: 'bruise'; "
                                      "'solver failure' when the nearest trial above it did "
                                      'not converge (the fruit bruises somewhere above '
                                      "max_force, not at it); 'grip not reached' when that "
                                      'trial\'s grip stayed below its command, undamaged '
                                      '(the fingers deliver no more); null without a finite '
                                      'max_force'),
    'min_estimate': Term('N', 'closed-form lower seed m g / (2 mu)'),
    'max_estimate': Term('N', 'closed-form upper seed (Hertz bruise force)'),
    'table_bruise_estimate': Term('N', 'closed-form table load at which the fruit bruises '
                                       'on the rigid table (Hertz): a fruit squeezed on the '
                                       'table is pressed into it too'),
    'mass': Term('kg', 'fruit mass'),
    'friction': Term('', 'friction coefficient at the jaws (pad friction under a pad)'),
    'tolerance': Term('', 'relative width at which the bisections stop'),
    'max_slip': Term('m', 'window.max_slip: the slip limit of a held trial'),
    'wall_time': Term('s', 'wall-clock time of the computation'),
    'trials': Term('-', 'every simulated grasp of the window (those its searches took, '
                        'in their serial order)'),
    'workers': Term('-', 'processes the window\'s trials ran on (window --workers)'),
    'look_ahead_trials': Term('-', 'trials run ahead on spare worker processes that the '
                                   'searches did not need (not in trials)'),
    'verdict': Term('-', 'a window trial\'s verdict: held, slipped or not reached (or '
                         'the run\'s outcome when it did not carry the fruit) for a hold '
                         'trial, bruised, safe or not reached for a bruise trial'),
    'kind': Term('-', 'a window trial\'s question: hold (does it hold?) or bruise (does '
                      'it bruise?)'),
    # analyze (a recording's summary.json; the unit is a suffix there)
    'file': Term('-', 'the recording analysed'),
    'fruit_state_topic': Term('-', 'topic of the FruitState messages read'),
    'left_wrench_topic': Term('-', 'topic of the left jaw\'s wrench'),
    'right_wrench_topic': Term('-', 'topic of the right jaw\'s wrench'),
    'samples': Term('-', 'FruitState messages read'),
    'start_time': Term('s', 'simulation time of the first message'),
    'time_of_peak_force': Term('s', 'when the grip force peaked'),
    'peak_left_force': Term('N', 'largest normal force on the left jaw'),
    'peak_right_force': Term('N', 'largest normal force on the right jaw'),
    'peak_compression_ratio': Term('', 'largest compression over the rest width'),
    'compression_at_peak_force': Term('m', 'compression at the peak grip force'),
    'stiffness': Term('N/m', 'tangent stiffness of the loading'),
    'secant_stiffness': Term('N/m', 'secant stiffness of the loading'),
    'stiffness_fit_force_range': Term('N', 'force range the stiffness is fitted on'),
    'stiffness_fit_compression_range': Term('m', 'compression range of the fit'),
    'stiffness_fit_time_range': Term('s', 'time range of the fit'),
    'stiffness_note': Term('-', 'why the tangent or secant stiffness is missing (too few '
                                'samples of the loading, no grip)'),
    'peak_contact_pressure': Term('Pa', 'largest contact pressure at any node, jaws or '
                                        'table, as recorded (FruitState.'
                                        'peak_contact_pressure)'),
    'peak_max_skin_strain': Term('', 'largest skin strain (signed)'),
    'gripped': Term('-', 'both jaws touched the fruit'),
    'held_slip_distance': Term('m', 'centroid drop relative to the jaws at the end of the '
                                    'hold (what analyze judges held and slipped on: a '
                                    'recording has no contact slide)'),
    'max_slip_distance': Term('m', 'largest centroid drop relative to the jaws over the '
                                   'recording'),
    'final_slip_distance': Term('m', 'centroid drop relative to the jaws at the last '
                                     'message'),
    'slipping_time': Term('s', 'time the fruit slid while gripped'),
    'final_bruised_fraction': Term('', 'bruised fraction at the last message'),
    'damage_note': Term('-', 'why a damage value is missing (old recordings)'),
    'bruise_threshold': Term('Pa', 'fruit.bruise_pressure of the recording'),
    'time_above_bruise_threshold': Term('s', 'time the damage pressure exceeded it'),
    'first_contact_time': Term('s', 'when both jaws first touched the fruit'),
    'event_times': Term('s', 'grip, lift-off, hold, drop: when each happened'),
    'contact_patches_at_peak_force': Term('-', '3D: per jaw (left, right) the contact '
                                                'patch at the peak grip force: its nodes '
                                                'and hull area (m^2)'),
    'slip_threshold': Term('m', 'the slip above which a grasp slipped (1 mm)'),
}

#: the node's Grasp action result field -> the key it reports
ACTION_RESULT_FIELDS: dict[str, str] = {
    'success': 'success', 'outcome': 'outcome', 'slipped': 'slipped',
    'bruised': 'bruised', 'crushed': 'crushed', 'message': 'message',
    'max_grip_force': 'peak_grip_force', 'final_gap': 'final_gap',
    'max_compression': 'peak_compression', 'max_contact_pressure': 'peak_jaw_pressure',
    'peak_damage_pressure': 'peak_damage_pressure', 'bruised_fraction': 'bruised_fraction',
    'slip_distance': 'slip_distance', 'dropped_at': 'dropped_at',
}

#: unit -> the suffix ``analyze`` appends to a key in summary.json ('' and '-': none)
ANALYZE_UNIT_SUFFIXES: dict[str, str] = {'N': '_n', 'm': '_m', 's': '_s', 'Pa': '_pa',
                                         'm^2': '_m2', 'kg': '_kg', 'N/m': '_n_per_m'}


def analyze_key(key: str) -> str:
    """The name of vocabulary ``key`` in ``analyze``'s summary.json (unit suffixed)."""
    return key + ANALYZE_UNIT_SUFFIXES.get(KEYS[key].unit, '')


def damage_fields(damage: Any) -> dict[str, Any]:
    """A ``Damage`` (2D or 3D) as vocabulary keys (JSON-ready)."""
    values: Mapping[str, Any] = damage.as_dict()
    return dict(bruised=bool(values['bruised']), crushed=bool(values['crushed']),
                bruised_length=float(values['bruised_length']),
                bruised_fraction=float(values['bruised_fraction']),
                peak_damage_pressure=float(values['peak_pressure']),
                peak_flesh_stress=float(values['peak_flesh_stress']))


#: first line of the README's glossary (``markdown_glossary``)
GLOSSARY_HEADER = '| outcome word | meaning |'


def markdown_glossary() -> str:
    """The README's glossary: the outcome words, the keys, the Grasp action's fields."""
    lines = [GLOSSARY_HEADER, '|---|---|']
    lines += [f'| `{word}` | {meaning} |' for word, meaning in OUTCOMES.items()]
    lines += ['', '| key | unit | meaning |', '|---|---|---|']
    lines += [f'| `{key}` | {term.unit} | {term.meaning} |' for key, term in KEYS.items()]
    lines += ['', '| Grasp action result field | key |', '|---|---|']
    lines += [f'| `{field}` | `{key}` |' for field, key in ACTION_RESULT_FIELDS.items()]
    return '\n'.join(lines)
