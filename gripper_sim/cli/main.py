"""Entry point of the ``gripper-sim`` console script.

Each verb lives in a module of this package exposing ``register(subparsers)``; the
module adds its parser(s) and sets ``handler(args) -> int`` as the parser default.
Modules import rclpy only inside their handlers, so offline verbs run without ROS.
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
import warnings

from gripper_sim import __version__, interrupts
from gripper_sim.errors import ConfigWarning, GripperSimError, Terminated

SIGPIPE_EXIT = 141   # 128 + SIGPIPE: what a shell reports for a tool a closed pipe ended
TERMINATED = 143     # 128 + SIGTERM: what a shell reports for a tool SIGTERM ended
VERB_MODULES = (
    'gripper_sim.cli.offline',
    'gripper_sim.cli.ros_commands',
    'gripper_sim.cli.bag_commands',
    'gripper_sim.cli.calibrate',
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
    """Run one verb: its exit code; 2 for a gripper_sim error (``error: ...``), 130 on
    Ctrl-C, 143 on a SIGTERM a verb handles (``errors.Terminated``), 141 when the reader
    of stdout has gone. Ctrl-C's KeyboardInterrupt comes where it breaks nothing
    (``gripper_sim.interrupts``: not inside numba's loading of a kernel, nor an import)
    unless a verb handles SIGINT itself."""
    previous = None
    if (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        previous = interrupts.install(lambda signum, frame: interrupts.interrupt(frame))
    try:
        code = _run(argv)
        sys.stdout.flush()   # here, not at exit: a closed pipe is then ours to handle
        return code
    except BrokenPipeError:
        return _reader_gone()
    except Terminated:
        return TERMINATED
    except KeyboardInterrupt:   # anywhere, the verbs' imports too
        return 130
    finally:
        if previous is not None:
            interrupts.restore(previous)


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra and not getattr(args, 'accepts_extra', False):
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    args.extra = extra
    if not getattr(args, 'handler', None):
        parser.print_help()
        return 2
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('default', ConfigWarning)   # each once
            warnings.showwarning = _show_warning
            return int(args.handler(args) or 0)
    except GripperSimError as err:
        print(f'error: {err}', file=sys.stderr)
        return 2


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line on stderr: ``warning: ...``."""
    print(f'warning: {message}', file=sys.stderr)


def _reader_gone() -> int:
    """The reader of stdout has gone (``gripper-sim info FILE | head -1``): stop quietly
    and exit 141 (128 + SIGPIPE) as Unix tools do, with no traceback.

    Later writes and the flush at exit go to /dev/null instead of the closed pipe.
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):   # stdout is not a file descriptor
        sys.stdout = os.fdopen(devnull, 'w')
    else:
        os.close(devnull)
    return SIGPIPE_EXIT


if __name__ == '__main__':
    sys.exit(main())
