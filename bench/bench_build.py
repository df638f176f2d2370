"""CPU time to build a simulation (``make_simulation``: the fruit's mesh, the energies,
the solver's sparse patterns and their symbolic factorisation, the first settled
state) for the 2D and 3D default set-ups, shell and solid, with either contact model.
Prints figures; asserts nothing.

Each set-up is built once untimed (numba's caches loaded), then ``--repeat`` times
timed (CPU time of this process, ``time.process_time``); the least is printed.
``--baseline DIR`` builds the same set-ups from another checkout too, the two trees
taking turns in fresh processes (``baseline.py``).

Usage::

    python bench/bench_build.py [--repeat 3] [--baseline DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

#: the checkout whose gripper_sim is measured: this one, or GRIPPER_SIM_TREE (--baseline)
TREE = Path(os.environ.get('GRIPPER_SIM_TREE') or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(TREE))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseline import add_arguments, alternated, best_by_key, parse_checked  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402

#: set-up name -> configuration overrides
SETUPS = {
    '2D shell': [],
    '2D shell, ipc': ['contact.model=ipc'],
    '2D solid': ['fruit.model=solid'],
    '3D shell': ['dimension=3'],
    '3D shell, ipc': ['dimension=3', 'contact.model=ipc'],
    '3D solid': ['dimension=3', 'fruit.model=solid'],
}


def build_time(overrides: list[str], repeat: int) -> float:
    """s, the least CPU time of ``repeat`` builds (after one untimed)."""
    config = load_config(overrides=overrides)
    make_simulation(config)
    best = float('inf')
    for _ in range(repeat):
        start = time.process_time()
        make_simulation(config)
        best = min(best, time.process_time() - start)
    return best


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=3)
    add_arguments(parser, 'each set-up once timed after one untimed build, as JSON (what '
                          '--baseline runs)')
    args = parse_checked(parser, argv)
    if args.plain:
        print(json.dumps({name: build_time(overrides, 1)
                          for name, overrides in SETUPS.items()}))
        return 0
    if args.baseline is None:
        tables = {'this': {name: build_time(overrides, args.repeat)
                           for name, overrides in SETUPS.items()}}
    else:
        outputs = alternated(Path(__file__).resolve(), args.baseline, ['--plain'],
                             args.repeat)
        tables = {label: best_by_key(runs, float) for label, runs in outputs.items()}
    print(f'load average {os.getloadavg()[0]:.2f}; CPU ms to build, best of {args.repeat}')
    labels = list(tables)
    print(f"{'set-up':16s}" + ''.join(f'{label:>10s}' for label in labels))
    for name in SETUPS:
        print(f'{name:16s}' + ''.join(f'{1e3 * tables[label][name]:10.0f}'
                                      for label in labels))
    return 0


if __name__ == '__main__':
    sys.exit(main())
