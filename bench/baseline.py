"""A benchmark run in this checkout and in another (``--baseline DIR``), taking turns.

Each run is a fresh process of the benchmark script measuring one tree's
``gripper_sim`` (``GRIPPER_SIM_TREE``, which the scripts put first on ``sys.path``) and
printing its figures as JSON on its last output line; the trees alternate so that a
change of the machine's load falls on both alike.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Callable

#: this checkout
THIS_TREE = Path(__file__).resolve().parents[1]


def checkout_problem(tree: Path) -> str | None:
    """Why ``tree`` is not a checkout of this project, or None if it is."""
    if (tree / 'gripper_sim' / 'core').is_dir():
        return None
    return f'--baseline {tree} is not a checkout of this project (no gripper_sim/core in it)'


def run_in_tree(script: Path, tree: Path, arguments: list[str]) -> Any:
    """The JSON of the last output line of ``script arguments`` run on ``tree``'s
    gripper_sim in a fresh process. SystemExit with the run's last error line if it
    fails."""
    env = dict(os.environ, GRIPPER_SIM_TREE=str(tree), PYTHONPATH=str(tree))
    child = subprocess.run([sys.executable, str(script), *arguments], env=env,
                           capture_output=True, text=True)
    lines = child.stdout.strip().splitlines()
    if child.returncode != 0 or not lines:
        last = (child.stderr.strip().splitlines() or ['no output'])[-1]
        raise SystemExit(f'error: {Path(script).name} {" ".join(arguments)} failed on '
                         f'{tree}: {last}')
    return json.loads(lines[-1])


def alternated(script: Path, baseline: Path, arguments: list[str],
               repeat: int) -> dict[str, list]:
    """{'this': outputs, 'baseline': outputs}: ``repeat`` runs of ``script arguments`` on
    each tree (``run_in_tree``), the trees taking turns."""
    trees = {'this': THIS_TREE, 'baseline': baseline.resolve()}
    outputs: dict[str, list] = {label: [] for label in trees}
    for _ in range(repeat):
        for label, tree in trees.items():
            outputs[label].append(run_in_tree(script, tree, arguments))
    return outputs


def best_by_key(outputs: list[dict], cost: Callable[[Any], float]) -> dict:
    """Of runs that each give {key: figures}: per key the figures of least ``cost``."""
    best: dict = {}
    for output in outputs:
        for key, figures in output.items():
            if key not in best or cost(figures) < cost(best[key]):
                best[key] = figures
    return best


def add_arguments(parser, plain_help: str) -> None:
    """``--baseline DIR`` and ``--plain`` (what a baseline run is: ``plain_help``)."""
    parser.add_argument('--baseline', type=Path, metavar='DIR',
                        help='another checkout to compare with, side by side')
    parser.add_argument('--plain', action='store_true', help=plain_help)


def argument_problem(args) -> str | None:
    """What is wrong with ``--repeat`` or ``--baseline`` of parsed ``args``, or None."""
    if args.repeat < 1:
        return f'--repeat must be at least 1, got {args.repeat}'
    return None if args.baseline is None else checkout_problem(args.baseline)


def parse_checked(parser, argv=None):
    """``parser.parse_args(argv)``, its ``--repeat`` and ``--baseline`` checked
    (``argument_problem``): SystemExit(2) with the problem on stderr if one is wrong."""
    args = parser.parse_args(argv)
    problem = argument_problem(args)
    if problem:
        print(f'error: {problem}', file=sys.stderr)
        raise SystemExit(2)
    return args
