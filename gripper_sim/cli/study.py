"""``gripper-sim study STUDY.yaml``: run a grasp study on Dask (``gripper_sim.workflows``)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from gripper_sim.cli import progress
from gripper_sim.cli.main import TERMINATED
from gripper_sim.cli.arguments import positive_int


def register(subparsers) -> None:
    study = subparsers.add_parser(
        'study', help='grasp study: population force windows over design axes, on Dask',
        description='Run every design point of a study file over its fruit population: '
                    "each fruit's grasp window (or a grip-force grid), the force range that "
                    'succeeds for a fraction of the population, rows as Parquet, a summary '
                    'JSON and an HTML/PNG report. Running it again resumes.')
    study.add_argument('study', metavar='STUDY',
                       help='a study file, or the name of one in config/studies')
    study.add_argument('--out', metavar='DIR', default=None,
                       help='results directory (default: study-results/NAME)')
    study.add_argument('--scheduler', metavar='tcp://HOST:PORT', default=None,
                       help='an existing Dask scheduler (default: a local cluster)')
    study.add_argument('--workers', type=positive_int, default=None, metavar='N',
                       help='local cluster: worker processes (default: the CPU count)')
    study.add_argument('--csv', action='store_true', help='also write rows.csv')
    study.add_argument('--no-report', action='store_true',
                       help='skip the HTML/PNG report')
    study.add_argument('--no-progress', action='store_true', help='no progress bar')
    study.set_defaults(handler=run_study_verb)


def run_study_verb(args) -> int:
    from gripper_sim.workflows.study import run_study, write_summary
    from gripper_sim.workflows.study_report import write_report
    from gripper_sim.workflows.study_spec import load_study
    if args.scheduler and args.workers is not None:
        from gripper_sim.workflows.study import StudyError
        raise StudyError('--workers sizes the local cluster: with --scheduler the '
                         "cluster's own workers run the study (start them with `dask "
                         'worker`)')
    study = load_study(args.study)
    out = Path(args.out or Path('study-results') / study.name)
    run = run_study(study, out, scheduler=args.scheduler, workers=args.workers,
                    progress=progress.wanted(args.no_progress))
    write_summary(run.summary, out / 'summary.json')
    if args.csv:
        from gripper_sim.workflows.study_results import RowStore
        RowStore(out).write_csv(out / 'rows.csv')
    if run.interrupted:
        print(f"{'terminated' if run.terminated else 'interrupted'}: {len(run.rows)} rows "
              f'kept in {out}/rows ({run.computed} computed now); run the same command '
              'again to resume', file=sys.stderr)
        return TERMINATED if run.terminated else 130
    if not args.no_report:
        write_report(run.summary, run.rows, out)
    summary = run.summary
    print(f"study {summary['study']}: {len(summary['points'])} design points x "
          f"{summary['population']['samples']} fruits, {summary['rows']} evaluations "
          f"({run.computed} computed, {run.reused} reused, {summary['errors']} with errors)")
    if summary['superseded']:
        print(f"  {summary['superseded']} rows of earlier code dropped (changed code computes "
              'its own)')
    percent = f"{summary['fraction'] * 100:g} %"
    for point in summary['points']:
        print(f"  {point['label']}: {describe_point(point, percent)}")
    print(f'  results in {out}/ (rows/*.parquet, summary.json'
          + (', rows.csv' if args.csv else '') + ('' if args.no_report else
                                                   ', report.html, report.png') + ')')
    failed = sum(len(point['failed']) for point in summary['points'])
    if failed:
        print(f"error: {failed} fruit task{'s' if failed > 1 else ''} failed (see above "
              'and summary.json): their design points have no population window',
              file=sys.stderr)
        return 2
    return 0


def describe_point(point: dict, percent: str) -> str:
    """A design point's line: its population window, or how many of its fruits failed
    (and the first failure) when any did."""
    failed = point['failed']
    if not failed:
        return describe_window(point.get('population'), percent)
    fruits = len(failed) + len(point['samples'])
    return (f'{len(failed)} of {fruits} fruits failed ({failed[0]["error"]}): no population '
            'window (run the study again to retry them)')


def describe_window(population: dict | None, percent: str) -> str:
    """One line: the population window with its interval, or 'no safe force', and what
    limited the fruits' own bounds where it was not a bruise or a slide."""
    if population is None:
        return 'not complete'
    window = population['window']
    if window is None:
        return (f"no safe force for {percent} of the fruits ({population['no_own_window']} "
                f"of {population['samples']} have no window of their own)"
                + _bound_notes(population))
    high = ('gripper.max_force' if window['high_is_limit'] else f"{window['high']:.3g} N")
    text = f"{window['low']:.3g} N .. {high} holds {percent} undamaged"
    ci = population['ci']
    if ci is not None:
        pct = f"{population['confidence'] * 100:g} %"
        text += (f" ({pct} CI: low {ci['low'][0]:.3g}-{ci['low'][1]:.3g} N, high "
                 f"{ci['high'][0]:.3g}-{ci['high'][1]:.3g} N)")
    sure = population['confident_window']
    if sure is None and not math.isnan(population['samples_needed']):
        text += f"; a confident claim needs >= {population['samples_needed']} fruits"
    return text + _bound_notes(population)


#: the population's counts of fruits whose bounds a solver failure or the fingers' reach
#: limited, and the study line's note on each ({n}: the count)
BOUND_NOTES = (
    ('solver_failure_bounds', "{n} fruits' upper bounds are solver failures, not bruises "
                              '(they bruise somewhere above)'),
    ('grip_limit_bounds', "{n} fruits' upper bounds are the most grip their fingers "
                          'delivered, not bruises (a larger command was not reached)'),
    ('solver_failure_holds_nowhere', '{n} fruits held at no force below one whose trial '
                                     'did not converge (whether they hold there is not '
                                     'known)'),
    ('grip_limit_holds_nowhere', '{n} fruits hold at no force their fingers deliver (the '
                                 'grips that might hold them were not reached)'),
)


def _bound_notes(population: dict) -> str:
    """'; ...' for each count of ``BOUND_NOTES`` above 0 (empty if none)."""
    return ''.join(f'; {note.format(n=population[key])}' for key, note in BOUND_NOTES
                   if population.get(key, 0))
