"""Study throughput: grasp evaluations per CPU-minute, 1 -> 2 worker scaling, and the
wall time of the README example study.

Prints figures, asserts nothing (a benchmark, not a test). CPU time is
``time.process_time`` in one process, and for a Dask run the user+system time of the
client and of every worker process (``os.times``, children included), so the figures
hold on a loaded machine.

1. In one process through the study path (``study_tasks.run_fruit``, what a worker
   runs): the cases one fruit's window search asks for, 2D with the study settings of
   ``config/studies/apple_friction.yaml``, 2D with the window's full scenario (1 ms),
   and 3D.
2. The same study on a local Dask cluster of 1 and of 2 workers: evaluations per
   CPU-minute of all processes, and the speed-up of the evaluation phase.
3. The README example study (``apple_friction``, about 1,000 evaluations) on the
   default local cluster: wall time, cluster start included.

Run: ``nice python bench/bench_study.py [--skip-3d] [--skip-example]``
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.workflows.scenario import load_scenario, scenario_config  # noqa: E402
from gripper_sim.workflows.study import run_study  # noqa: E402
from gripper_sim.workflows.study_spec import Study, load_study  # noqa: E402
from gripper_sim.workflows.study_tasks import run_fruit  # noqa: E402
from gripper_sim.workflows.window import trial_setup  # noqa: E402

EXAMPLE = 'apple_friction'


def in_process(config, scenario, tolerance: float, label: str) -> None:
    """One fruit's window search through ``run_fruit`` (what a worker runs)."""
    config, scenario = trial_setup(config, scenario)
    run_fruit(config, scenario, 0.5, (), {})  # load the kernels once
    start = time.process_time()
    done = run_fruit(config, scenario, tolerance, (), {})
    total = time.process_time() - start
    count = len(done['new'])
    low, high = done['result']
    print(f'  {label:44s} {count:3d} evaluations, {total / count * 1e3:7.1f} ms CPU '
          f'each: {60 * count / total:7.0f} per CPU-minute (window {low:.3g} .. '
          f'{high:.3g} N)', flush=True)


def cpu_seconds() -> float:
    """User + system CPU of this process and of its exited (waited-for) children, s."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def on_cluster(study: Study, workers: int) -> float:
    """Run ``study`` on a fresh local cluster of ``workers``; prints figures, returns the
    evaluations per second of wall time (cluster start excluded)."""
    before = cpu_seconds()
    with tempfile.TemporaryDirectory() as out:
        run = run_study(study, out, workers=workers, progress=False)
    cpu = cpu_seconds() - before  # the workers have exited: their CPU is counted
    rows = run.computed
    task_cpu = sum(r['cpu_time'] for r in run.rows)
    rate = rows / run.run_time
    print(f'  {workers} worker(s): {rows} evaluations in {run.run_time:.1f} s wall '
          f'({rate:.1f}/s; cluster start {run.startup_time:.1f} s); CPU: in the tasks '
          f'{task_cpu:.1f} s ({60 * rows / task_cpu:.0f} per CPU-minute), all processes '
          f'{cpu:.1f} s ({60 * rows / cpu:.0f} per CPU-minute)', flush=True)
    return rate


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--skip-3d', action='store_true')
    parser.add_argument('--skip-example', action='store_true')
    parser.add_argument('--only-example', action='store_true')
    parser.add_argument('--samples', type=int, default=6,
                        help='fruits per design point of the scaling study (default 6)')
    args = parser.parse_args()
    print(f'load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores')
    example = load_study(EXAMPLE)
    if not args.only_example:
        print('1. one process, through the study path (run_fruit), one window search:')
        setup = example.trial(example.points[1], 0, {})
        scenario = example.base['scenario']
        config = dict(setup.config)
        config['gripper.initial_lift'] += scenario['approach.height']
        in_process(config, scenario, example.tolerance,
                   f"2D study settings (dt {config['sim.dt'] * 1e3:g} ms, short lift)")
        full = load_scenario('pick_and_place')
        in_process(scenario_config(full), full, example.tolerance,
                   '2D window defaults (pick_and_place, dt 1 ms)')
        if not args.skip_3d:
            config3d = scenario_config(scenario, overrides={
                'dimension': 3, 'sim.dt': 0.02, 'fruit.mesh.subdivisions': 4})
            in_process(config3d, scenario, 0.1, '3D study settings (dt 20 ms, 162 vertices)')
        print(f'2. local Dask cluster, {EXAMPLE} with {args.samples} fruits per design point:')
        small = replace(example, population=replace(example.population,
                                                    samples=args.samples))
        one = on_cluster(small, 1)
        two = on_cluster(small, 2)
        print(f'  scaling 1 -> 2 workers: {two / one:.2f}x (evaluations per second of wall '
              'time, cluster start excluded)')
    if not args.skip_example:
        print(f'3. the README example study ({EXAMPLE}), default local cluster:')
        start, before = time.perf_counter(), cpu_seconds()
        with tempfile.TemporaryDirectory() as out:
            run = run_study(example, out, progress=False)
        wall, cpu = time.perf_counter() - start, cpu_seconds() - before
        task_cpu = sum(r['cpu_time'] for r in run.rows)
        print(f'  {run.computed} evaluations in {wall:.0f} s wall (cluster start '
              f'{run.startup_time:.1f} s); CPU: in the tasks {task_cpu:.1f} s '
              f'({60 * run.computed / task_cpu:.0f} per CPU-minute), all processes '
              f'{cpu:.1f} s ({60 * run.computed / cpu:.0f} per CPU-minute)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
