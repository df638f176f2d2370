"""Offline verbs (no ROS graph): ``squeeze``, ``pick``, ``run``, ``window``, ``fingers``
and ``fruits``. With ``--set dimension=3`` the simulation verbs run the 3D model
(``gripper_sim.core.make_simulation``) and report contact areas (mm^2) and patch radii
instead of contact lengths."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from gripper_sim.cli.arguments import non_negative_float, positive_float, positive_int
from gripper_sim.cli.progress import StepProgress
from gripper_sim.configuration import (RIGID_FINGERS, available_fruits, load_config,
                                       parse_override)
from gripper_sim.errors import GripperSimError


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """--fruit / --config / --set, shared by every verb that builds a simulation."""
    parser.add_argument('--fruit', help='fruit preset name (see: gripper-sim fruits), or a '
                        'preset file (.yaml, e.g. from gripper-sim calibrate)')
    parser.add_argument('--config', metavar='FILE', help='YAML configuration file, layered '
                        "over the fruit preset (--fruit, else its own 'fruit:', else the "
                        'default fruit)')
    parser.add_argument('--set', metavar='KEY=VALUE', action='append', default=[],
                        dest='overrides', help='override a configuration key (repeatable); '
                        'fruit=NAME and finger=NAME select presets')


def config_from_args(args, forced: dict | None = None) -> dict:
    """The validated configuration the arguments ask for.

    ``forced`` holds defaults of the verb (e.g. gravity off for squeeze) that apply
    unless the user set that key with --set.
    """
    user = dict(parse_override(text) for text in args.overrides)
    merged = dict(forced or {})
    merged.update(user)
    return load_config(fruit=args.fruit, config_file=args.config, overrides=merged,
                       finger=getattr(args, 'finger', None))


def register(subparsers) -> None:
    squeeze = subparsers.add_parser(
        'squeeze', help='plate compression test (ASAE S368 style) of a fruit',
        description='Close the jaws (rigid flat plates unless --finger) slowly on the fruit '
                    'until a force or a gap is reached. Gravity and the table are off unless '
                    'set with --set.')
    _add_fruit_finger_arguments(squeeze)
    target = squeeze.add_mutually_exclusive_group(required=True)
    target.add_argument('--to-force', type=positive_float, metavar='N',
                        help='stop when the mean jaw normal force reaches N newtons')
    target.add_argument('--to-gap', type=non_negative_float, metavar='M',
                        help='stop when the jaw gap reaches M metres')
    squeeze.add_argument('--speed', type=positive_float, metavar='M_PER_S', default=0.005,
                         help='gap closing rate, m/s (default 0.005)')
    _add_output_arguments(squeeze)
    squeeze.set_defaults(handler=run_squeeze)

    pick = subparsers.add_parser(
        'pick', help='close to a grip force, lift and hold the fruit',
        description='Close the jaws on the fruit resting on the table to a grip force, '
                    'lift it and hold it; reports held, slipped (slid more than 1 mm down '
                    'the jaws at its contacts) or dropped (lost from the jaws, or its '
                    'centroid more than 10 mm behind them).')
    _add_fruit_finger_arguments(pick)
    pick.add_argument('--force', type=positive_float, required=True, metavar='N',
                      help='grip force (mean jaw normal force), N')
    pick.add_argument('--lift', type=non_negative_float, default=0.05, metavar='M',
                      help='lift height, m (default 0.05)')
    pick.add_argument('--hold', type=non_negative_float, default=1.0, metavar='S',
                      help='hold time after lifting, s (default 1)')
    pick.add_argument('--speed', type=positive_float, metavar='M_PER_S', default=None,
                      help='gap closing rate, m/s (default: gripper.close_speed)')
    _add_output_arguments(pick)
    pick.set_defaults(handler=run_pick)

    run = subparsers.add_parser(
        'run', help='run a pick-and-place scenario (config/scenarios/*.yaml)',
        description='Approach, close, squeeze, lift, transport sideways, lower onto the '
                    'table, open and retreat, as the scenario file says; reports placed, '
                    'dropped (and when), slipped, bruised or crushed. Exit 0 if placed.')
    run.add_argument('scenario', metavar='SCENARIO',
                     help='a scenario file, or the name of one in config/scenarios')
    _add_fruit_finger_arguments(run)
    run.add_argument('--force', type=positive_float, metavar='N', default=None,
                     help="grip force, N (overrides the scenario's close.force; force mode)")
    _add_output_arguments(run)
    run.set_defaults(handler=run_scenario_verb)

    window = subparsers.add_parser(
        'window', help='the grasp window: grip forces that hold without bruising',
        description='Find by simulation the smallest grip force that holds the fruit '
                    "through the scenario's lift and transport, and the largest force "
                    'that does not bruise it; prints the safe window or says there is none.')
    _add_fruit_finger_arguments(window)
    window.add_argument('--scenario', default='pick_and_place', metavar='SCENARIO',
                        help='scenario giving the close speed, lift and transport '
                             '(default: pick_and_place)')
    window.add_argument('--tolerance', type=positive_float, default=None, metavar='REL',
                        help='relative width at which the bisections stop (default 0.03)')
    window.add_argument('--json', action='store_true', help='print one JSON object')
    window.add_argument('--html', metavar='FILE.html',
                        help='also write an HTML report of the trials (opens offline)')
    window.add_argument('--quiet', action='store_true', help='no line per trial')
    window.add_argument('--workers', type=positive_int, default=1, metavar='N',
                        help='processes running trials (default 1); from 2 the hold and '
                             'bruise searches run side by side and spare processes try '
                             'the forces a search may need next: the same trials and '
                             'window, sooner')
    window.set_defaults(handler=run_window)

    fingers = subparsers.add_parser('fingers', help='list the finger presets')
    fingers.add_argument('--json', action='store_true', help='print JSON')
    fingers.set_defaults(handler=run_fingers)

    fruits = subparsers.add_parser('fruits', help='list the fruit presets')
    fruits.add_argument('--json', action='store_true', help='print JSON')
    fruits.set_defaults(handler=run_fruits)


def _add_fruit_finger_arguments(parser) -> None:
    """--fruit / --config / --finger / --set of the simulating verbs."""
    add_config_arguments(parser)
    parser.add_argument('--finger', metavar='NAME',
                        help='finger preset (config/fingers: see gripper-sim fingers)')


def _add_output_arguments(parser) -> None:
    parser.add_argument('--json', action='store_true',
                        help='print one JSON object with the time series and summary')
    parser.add_argument('--out', metavar='FILE.mcap',
                        help='record every step to an MCAP file, as the node would publish')
    parser.add_argument('--html', metavar='FILE.html',
                        help='also write an HTML report of the run (plots and an animation '
                             'of the fruit; opens offline)')
    parser.add_argument('--quiet', action='store_true',
                        help='no progress bar (it shows on a terminal after 2 s)')


class _Series:
    """Collects the time series, the peaks (``core.peaks.RunPeaks``) and the contact size
    every verb reports.

    Contact size: in 2D the contact length (m, both jaws); in 3D the contact area
    (m^2, both jaws, ``Deformation3D.contact_area``) and the larger of the two jaws'
    patch radii (m), each at the step of peak grip force and at its largest.
    """

    def __init__(self, dimension: int = 2):
        from gripper_sim.core.peaks import RunPeaks
        self.dimension = int(dimension)
        self.time, self.gap, self.force = [], [], []
        self.peaks = RunPeaks()
        self.peak_contact = 0.0
        self.contact_at_peak_force = 0.0
        self.patch_radius_at_peak_force = 0.0
        self.peak_patch_radius = 0.0

    def __call__(self, result) -> None:
        deformation = result.deformation
        self.time.append(round(result.time, 9))
        self.gap.append(result.gap)
        self.force.append(result.grip_force)
        if self.dimension == 3:
            contact = float(deformation.contact_area)
            radius = float(max(deformation.jaw_contact_radii))
        else:
            contact, radius = float(deformation.contact_length), 0.0
        if result.grip_force > self.peaks.grip_force or not self.time[:-1]:
            self.contact_at_peak_force = contact
            self.patch_radius_at_peak_force = radius
        self.peaks(result)
        self.peak_contact = max(self.peak_contact, contact)
        self.peak_patch_radius = max(self.peak_patch_radius, radius)

    def arrays(self) -> dict:
        return dict(time=self.time, gap=self.gap, force=self.force)

    def contact_summary(self) -> dict:
        """JSON fields of the contact size (see the class docstring)."""
        if self.dimension == 3:
            return dict(dimension=3, peak_contact_area=self.peak_contact,
                        contact_area_at_peak_force=self.contact_at_peak_force,
                        peak_patch_radius=self.peak_patch_radius,
                        patch_radius_at_peak_force=self.patch_radius_at_peak_force)
        return dict(dimension=2, peak_contact_length=self.peak_contact,
                    contact_length_at_peak_force=self.contact_at_peak_force)

    def contact_lines(self, width: int) -> list[str]:
        """Text lines of the contact size, labels padded to ``width``."""
        if self.dimension == 3:
            return [f"{'contact area':{width}s} {self.contact_at_peak_force * 1e6:.4g} mm^2 at "
                    f'peak force (both jaws; largest {self.peak_contact * 1e6:.4g} mm^2)',
                    f"{'contact patch radius':{width}s} "
                    f'{self.patch_radius_at_peak_force * 1e3:.3g} mm at peak force (larger jaw)']
        return [f"{'contact length':{width}s} {self.contact_at_peak_force * 1e3:.4g} mm at "
                'peak force (both jaws, planar)']


def _measure_lines(summary: dict, dimension: int, width: int) -> list[str]:
    """The text lines every simulation verb prints for the same keys (labels padded to
    ``width``): peak grip force, compression, jaw and table pressure, damage."""
    how, of_what = _damage_note(dimension)
    return [
        f"{'peak grip force':{width}s} {summary['peak_grip_force']:.4g} N (measured)",
        f"{'peak compression':{width}s} {summary['peak_compression'] * 1e3:.4g} mm",
        f"{'peak jaw pressure':{width}s} {summary['peak_jaw_pressure'] / 1e3:.4g} kPa "
        f'({_pressure_note(dimension)})',
        f"{'peak table pressure':{width}s} {summary['peak_table_pressure'] / 1e3:.4g} kPa",
        f"{'damage':{width}s} peak damage pressure "
        f"{summary.get('peak_damage_pressure', 0.0) / 1e3:.4g} kPa ({how}), "
        + ('bruised' if summary['bruised'] else 'not bruised')
        + f" ({summary.get('bruised_fraction', 0.0) * 100:.1f} % of the {of_what})"
        + (', crushed' if summary['crushed'] else ''),
    ]


def _pressure_note(dimension: int) -> str:
    """How the contact pressure was found, for the text output."""
    return 'resolved over the contact patch' if dimension == 3 else 'planar line contact'


def _damage_note(dimension: int) -> tuple[str, str]:
    """(how the damage pressure was found, what the bruised fraction is a fraction of)."""
    return ('resolved', 'surface area') if dimension == 3 else ('Hertz', 'outline')


def check_outputs(args) -> None:
    """GripperSimError unless every output file the verb's options name can be written
    (``check_output_file``): ``--out`` (a new recording) and ``--html`` (a report,
    replaced if it exists). Called before the simulation, which must not run for minutes
    to fail at its end."""
    if getattr(args, 'out', None):
        check_output_file(args.out, '--out', replace=False)
    if getattr(args, 'html', None):
        check_output_file(args.html, '--html', replace=True)


def check_output_file(path: str, option: str, *, replace: bool) -> None:
    """GripperSimError unless a file can be written at ``path`` (the value of ``option``):
    not a directory, in an existing folder that takes a new file; an existing file only
    where ``replace`` (recordings are never written over) and if it can be written.

    The folder is tried by creating the file and removing it again: ``os.access`` says
    yes to root on a read-only or virtual file system (/sys)."""
    target = Path(path).expanduser()
    if target.is_dir():
        raise GripperSimError(f'cannot write {option} {path}: it is a directory; give a '
                              'file name')
    if target.exists():
        if not replace:
            raise GripperSimError(f'cannot write {option} {path}: it already exists; choose '
                                  'another name or remove it (recordings are never '
                                  'overwritten)')
        mode = 'ab'   # opened, not written: its contents stay
    elif not target.parent.is_dir():
        raise GripperSimError(f"cannot write {option} {path}: there is no directory "
                              f"'{target.parent}'")
    else:
        mode = 'xb'
    try:
        with open(target, mode):
            pass
    except OSError as err:
        raise GripperSimError(f'cannot write {option} {path}: {err.strerror}') from None
    if mode == 'xb':
        target.unlink()


def _dimension(sim) -> int:
    return int(getattr(sim, 'dimension', 2))


def _start_observers(stack: ExitStack, args, sim, verb: str):
    """Progress bar and recording of a run (``--quiet``, ``--out``, ``--html``); the
    recorder or None. Without ``--out``, ``--html`` records to a temporary file."""
    sim.add_observer(stack.enter_context(StepProgress(verb, quiet=args.quiet)))
    path = args.out
    if not path and args.html:
        folder = stack.enter_context(tempfile.TemporaryDirectory(prefix='gripper_sim_'))
        path = os.path.join(folder, 'run.mcap')
    if not path:
        return None
    from gripper_sim.recording.offline import SimRecorder
    from gripper_sim.recording.errors import RecordingError
    try:
        recorder = stack.enter_context(SimRecorder(path, sim.config, initial=sim.last))
    except RecordingError as err:
        raise GripperSimError(str(err)) from err
    sim.add_observer(recorder.on_step)
    return recorder


def _write_html(args, recorder) -> None:
    """``--html``: close the recording and write its report (call inside the stack)."""
    if recorder is None or not args.html:
        return
    from gripper_sim.recording.analysis import write_recording_report
    from gripper_sim.recording.errors import RecordingError
    recorder.close()
    try:
        write_recording_report(recorder.path, args.html)
    except RecordingError as err:
        raise GripperSimError(str(err)) from err
    print(f'wrote {args.html}', file=sys.stderr)


def run_squeeze(args) -> int:
    from gripper_sim.core.vocabulary import damage_fields
    from gripper_sim.workflows.factory import make_simulation as Simulation
    from gripper_sim.workflows.squeeze import (SQUEEZE_DEFAULTS, check_squeeze, squeeze,
                                              stopped_at_max_effort)
    check_outputs(args)
    config = config_from_args(args, SQUEEZE_DEFAULTS)
    check_squeeze(config, args.speed, args.to_force)
    sim = Simulation(config)
    series = _Series(_dimension(sim))
    sim.add_observer(series)
    with ExitStack() as stack:
        recorder = _start_observers(stack, args, sim, 'squeeze')
        squeeze(sim, args.speed, to_force=args.to_force, to_gap=args.to_gap)
        _write_html(args, recorder)
    summary = dict(fruit=config['fruit.name'], model=config['fruit.model'],
                   **series.peaks.as_dict(), final_gap=sim.last.gap,
                   duration=sim.time, steps=sim.last.step,
                   **damage_fields(sim.last.damage), **series.contact_summary())
    if args.json:
        json.dump(dict(series.arrays(), summary=summary), sys.stdout)
        sys.stdout.write('\n')
    else:
        dim = series.dimension
        print(f"squeeze of {config['fruit.name']} ({config['fruit.model']} model, {dim}D) "
              f"with the {config['gripper.finger.name']} finger, {sim.time:.3f} s simulated "
              f'in {sim.last.step} steps')
        for line in _measure_lines(summary, dim, 21) + series.contact_lines(21):
            print(f'  {line}')
        print(f"  {'final gap':21s} {summary['final_gap'] * 1e3:.4g} mm")
        if stopped_at_max_effort(sim, sim.last):
            print(f"  the jaws stopped at their maximum effort (gripper.max_force "
                  f"{config['gripper.max_force']:g} N) before the gap target")
    return 0


def run_pick(args) -> int:
    from gripper_sim.workflows.grasp import GraspSequence, run_grasp
    from gripper_sim.workflows.factory import make_simulation as Simulation
    check_outputs(args)
    config = config_from_args(args)
    if config['gripper.initial_lift'] is None and config['world.table']:
        # the jaws start at the grasp height: the fruit's centre, or higher where a small
        # fruit's centre would put the jaws into the table
        from gripper_sim.workflows.scenario import grasp_height
        config = config_from_args(args, {'gripper.initial_lift': grasp_height(config)})
    sim = Simulation(config)
    series = _Series(_dimension(sim))
    sim.add_observer(series)
    with ExitStack() as stack:
        recorder = _start_observers(stack, args, sim, 'pick')
        sequence = GraspSequence(sim, args.force, args.speed, args.lift, args.hold)
        summary = run_grasp(sim, sequence)
        _write_html(args, recorder)
    summary = dict(fruit=config['fruit.name'], finger=config['gripper.finger.name'],
                   **summary, **series.contact_summary())
    if args.json:
        json.dump(dict(outcome=summary['outcome'], slip_distance=summary['slip_distance'],
                       **series.arrays(), summary=summary), sys.stdout)
        sys.stdout.write('\n')
    else:
        dim = series.dimension
        print(f"pick of {config['fruit.name']} ({dim}D) with the "
              f"{config['gripper.finger.name']} finger at {args.force:g} N: "
              f"{summary['outcome']}")
        print(f"  {summary['message']}")
        print(f"  {'slip in the jaws':26s} {summary['slip_distance'] * 1e3:.3f} mm")
        print(f"  {'centroid drop':26s} {summary['centroid_drop'] * 1e3:.3f} mm "
              '(relative to the jaws, elastic sag included)')
        for line in _measure_lines(summary, dim, 26) + series.contact_lines(26):
            print(f'  {line}')
    return 0 if summary['outcome'] == 'held' else 1


def run_fruits(args) -> int:
    from gripper_sim.core.fruit import build_fruit
    rows = []
    for name in available_fruits():
        config = load_config(fruit=name)
        fruit = build_fruit(config)
        outline = fruit.rest_positions[fruit.surface]
        rows.append(dict(name=name, model=config['fruit.model'],
                         shape=config['fruit.shape.type'],
                         diameter=config['fruit.shape.diameter'],
                         width=float(np.ptp(outline[:, 0])),
                         height=float(np.ptp(outline[:, 1])),
                         mass=fruit.total_mass,
                         density=config['fruit.density'],
                         youngs_modulus=config['fruit.flesh.youngs_modulus'],
                         poisson_ratio=config['fruit.flesh.poisson_ratio'],
                         jaw_friction=config['contact.jaw.static_friction'],
                         pad_friction=config['contact.pad.friction'],
                         table_friction=config['contact.table.static_friction'],
                         bruise_pressure=config['fruit.bruise_pressure'],
                         failure_stress=config['fruit.failure_stress'],
                         failure_strain=config['fruit.failure_strain']))
    if args.json:
        json.dump(rows, sys.stdout)
        sys.stdout.write('\n')
        return 0
    print(f"{'fruit':11s} {'model':5s} {'shape':7s} {'w x h mm':>11s} {'mass g':>6s} "
          f"{'E MPa':>6s} {'nu':>4s} {'mu jaw':>6s} {'mu pad':>6s} {'bruise kPa':>10s} "
          f"{'fail kPa':>8s}")
    for r in rows:
        size = f"{r['width'] * 1e3:.0f} x {r['height'] * 1e3:.0f}"
        print(f"{r['name']:11s} {r['model']:5s} {r['shape']:7s} {size:>11s} "
              f"{r['mass'] * 1e3:6.0f} {r['youngs_modulus'] / 1e6:6.2f} "
              f"{r['poisson_ratio']:4.2f} {r['jaw_friction']:6.2f} {r['pad_friction']:6.2f} "
              f"{r['bruise_pressure'] / 1e3:10.0f} {r['failure_stress'] / 1e3:8.0f}")
    print('sources and estimates: the comments in config/fruits/NAME.yaml')
    return 0


def run_scenario_verb(args) -> int:
    from gripper_sim.workflows.scenario import load_scenario, run_scenario, scenario_config
    from gripper_sim.workflows.factory import make_simulation as Simulation
    check_outputs(args)
    scenario = load_scenario(args.scenario)
    if args.force is not None:
        scenario = scenario.with_values(close__mode='force', close__force=args.force)
    config = scenario_config(scenario, fruit=args.fruit, finger=args.finger,
                             config_file=args.config, overrides=args.overrides)
    if scenario['close.mode'] == 'force' and scenario['close.force'] > config['gripper.max_force']:
        raise GripperSimError(f"grip force {scenario['close.force']} N exceeds "
                              f"gripper.max_force {config['gripper.max_force']} N")
    sim = Simulation(config)
    series = _Series(_dimension(sim))
    sim.add_observer(series)
    with ExitStack() as stack:
        recorder = _start_observers(stack, args, sim, scenario['name'])
        summary = run_scenario(sim, scenario)
        _write_html(args, recorder)
    summary = dict(scenario=scenario['name'], fruit=config['fruit.name'],
                   finger=config['gripper.finger.name'], **summary,
                   **series.contact_summary())
    if args.json:
        json.dump(dict(outcome=summary['outcome'], **series.arrays(), summary=summary),
                  sys.stdout)
        sys.stdout.write('\n')
    else:
        how = (f"{scenario['close.force']:g} N" if scenario['close.mode'] == 'force'
               else f"gap {scenario['close.gap']:g} m")
        print(f"{scenario['name']}: {config['fruit.name']} ({series.dimension}D) with the "
              f"{config['gripper.finger.name']} finger at {how}: {summary['outcome']}")
        if summary['message']:
            print(f"  {summary['message']}")
        phases = ', '.join(f'{name} {t:.2f}' for name, t in summary['phase_times'].items())
        print(f'  phases (s): {phases}')
        print(f"  {'slip in the jaws':26s} {summary['slip_distance'] * 1e3:.3f} mm")
        for line in _measure_lines(summary, series.dimension, 26):
            print(f'  {line}')
        for line in series.contact_lines(26):
            print(f'  {line}')
    return 0 if summary['outcome'] == 'placed' else 1


def run_window(args) -> int:
    from gripper_sim.workflows.scenario import load_scenario, scenario_config
    from gripper_sim.workflows.window import (TOLERANCE, bruise_trial_above, grasp_window,
                                              reach_bracket)
    check_outputs(args)
    scenario = load_scenario(args.scenario)
    config = scenario_config(scenario, fruit=args.fruit, finger=args.finger,
                             config_file=args.config, overrides=args.overrides)
    tolerance = args.tolerance if args.tolerance is not None else TOLERANCE
    if tolerance >= 1:
        raise GripperSimError(f'--tolerance {tolerance} must be below 1')

    def progress(trial):
        if not args.json and not args.quiet:
            print(f'  {_trial_line(trial)} ({trial.wall_time:.1f} s)', flush=True)

    if not args.json:
        print(f"grasp window of {config['fruit.name']} ({int(config['dimension'])}D) with the "
              f"{config['gripper.finger.name']} finger ({scenario['name']}: lift "
              f"{scenario['lift.height']:g} m, transport {scenario['transport.distance']:g} m)",
              flush=True)
    window = grasp_window(config, scenario, tolerance, progress, workers=args.workers)
    if args.html:
        from gripper_sim.recording.analysis.report_html import write_window_report
        from gripper_sim.recording.errors import RecordingError
        try:
            write_window_report(window.as_dict(), args.html, title=(
                f"Grasp window of {config['fruit.name']} with the "
                f"{config['gripper.finger.name']} finger ({scenario['name']})"),
                bruise_pressure=float(config['fruit.bruise_pressure']))
        except RecordingError as err:
            raise GripperSimError(str(err)) from err
        print(f'wrote {args.html}', file=sys.stderr)
    if args.json:
        json.dump(window.as_dict(), sys.stdout)
        sys.stdout.write('\n')
        return 0
    limit = config['gripper.max_force']

    def bound(force, measured):
        return f'{force:.3g} N commanded, {measured:.3g} N measured peak grip force' \
            if measured is not None else f'{force:.3g} N commanded'

    low = ('none up to gripper.max_force' if window.min_force is None
           else bound(window.min_force, window.min_force_measured))
    if window.min_force_limited_by == 'grip not reached':
        slid, unreached = reach_bracket(window.trials)
        low = ('not found: ' + (f'slides at {slid.force:.3g} N, ' if slid else '')
               + f'does not reach a grip of {unreached.force:.3g} N (peak '
               f'{unreached.peak_grip_force:.3g} N): the fingers deliver no more')
    elif window.min_force_limited_by == 'solver failure':
        low = (f'not found up to gripper.max_force ({limit:g} N): the trial there did not '
               'converge, so whether it holds is not known')
    high = (f'none up to gripper.max_force ({limit:g} N)' if window.max_force == math.inf
            else 'bruised at every force tried' if window.max_force is None
            else bound(window.max_force, window.max_force_measured))
    if window.max_force_limited_by in ('solver failure', 'grip not reached'):
        high = f'not found: safe up to {high}'
    print(f'  holds from      {low}')
    print(f'                  (slides less than window.max_slip = {window.max_slip * 1e3:g} mm;'
          f' m g / (2 mu) = {window.min_estimate:.3g} N, m = {window.mass * 1e3:.0f} g, '
          f'mu = {window.friction:g})')
    print(f'  bruises above   {high}')
    sites = sorted({t.bruised_at for t in window.trials if t.bruised and t.bruised_at})
    finger = config['gripper.finger.type']
    rigid = ('' if finger in RIGID_FINGERS
             else f" for rigid jaws, the search's start: the {finger} finger is softer")
    print(f'                  (Hertz estimate at the jaws {window.max_estimate:.3g} N{rigid}'
          + (', 3D: resolved pressure' if int(config['dimension']) == 3 else '')
          + (f'; on the table once it carries {window.table_bruise_estimate:.3g} N'
             if window.table_bruise_estimate else '')
          + (f"; bruised at the {' and the '.join(sites)}" if sites else '') + ')')
    if window.max_force_limited_by == 'solver failure':
        print('                  (the nearest trial above did not converge: the fruit '
              'bruises somewhere above this force, not at it)')
    elif window.max_force_limited_by == 'grip not reached':
        above = bruise_trial_above(window.max_force, window.trials)
        print(f'                  (the nearest trial above, {above.force:.3g} N, did not '
              f'reach its grip: peak {above.peak_grip_force:.3g} N, not bruised; the '
              'fingers deliver no more)')
    if window.exists:
        top = 'gripper.max_force' if window.max_force == math.inf else \
            f'{window.max_force:.3g} N'
        print(f'  safe window     {window.min_force:.3g} N .. {top} commanded')
    else:
        print('  safe window     none')
    extra = (f' on {window.workers} processes (and {window.look_ahead_trials} tried ahead '
             'that the searches did not need)' if window.workers > 1 else '')
    print(f'  {len(window.trials)} simulations in {window.wall_time:.1f} s{extra}')
    return 0


def _trial_line(trial) -> str:
    """One window trial as text: its verdict (held/slipped, bruised/safe), slip, forces
    and the jaws' pressure apart from the table's."""
    return (f'{trial.kind:6s} trial {trial.force:8.3f} N: {trial.verdict:8s} slip '
            f'{trial.slip_distance * 1e3:6.3f} mm, peak grip force '
            f'{trial.peak_grip_force:7.3f} N, jaw pressure '
            f'{trial.peak_jaw_pressure / 1e3:6.1f} kPa, table '
            f'{trial.peak_table_pressure / 1e3:5.1f} kPa, damage '
            f'{trial.peak_damage_pressure / 1e3:6.1f} kPa'
            + (f' at the {trial.bruised_at}' if trial.bruised and trial.bruised_at else ''))


def run_fingers(args) -> int:
    from gripper_sim.configuration import available_fingers, finger_preset_path, read_yaml
    from gripper_sim.configuration import flatten as flat_keys
    rows = []
    for name in available_fingers():
        keys = flat_keys(read_yaml(finger_preset_path(name)))
        rows.append(dict(name=name, **{k: v for k, v in keys.items()}))
    if args.json:
        json.dump(rows, sys.stdout)
        sys.stdout.write('\n')
        return 0
    for row in rows:
        settings = ', '.join(f'{k.replace("gripper.finger.", "")}={v}'
                             for k, v in row.items() if k != 'name')
        print(f"{row['name']:12s} {settings}")
    return 0
