"""Entry point of the ``gripper-sim`` console script.

Each verb lives in a module of this package exposing ``register(subparsers)``; the
module adds its parser(s) and sets ``handler(args) -> int`` as the parser default.
Modules import rclpy only inside their handlers, so offline verbs run without ROS.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from gripper_sim import __version__
from gripper_sim.errors import GripperSimError

VERB_MODULES = (
    'gripper_sim.cli.offline',
    'gripper_sim.cli.ros_commands',
    'gripper_sim.cli.bag_commands',
    'gripper_sim.cli.study',
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='gripper-sim',
        description='Simulate a parallel-jaw gripper grasping a deformable fruit.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    subparsers = parser.add_subparsers(dest='verb', metavar='VERB')
    for name in VERB_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name == name:
                continue
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra and not getattr(args, 'accepts_extra', False):
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.extra = extra
    if not getattr(args, 'handler', None):
        parser.print_help()
        return 2
    try:
        return int(args.handler(args) or 0)
    except GripperSimError as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
