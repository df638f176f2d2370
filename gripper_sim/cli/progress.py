"""Progress bars of the offline verbs (tqdm, on stderr).

A bar appears only when the work has run for ``DELAY`` seconds, and never with
``--quiet`` or when stderr is not a terminal (a pipe, a log file, a test): short runs
and scripts see nothing.
"""
from __future__ import annotations

import sys
from typing import Any

from tqdm import tqdm

#: s before a bar appears
DELAY = 2.0


def wanted(quiet: bool) -> bool:
    """Whether to show progress: not ``quiet`` and stderr is a terminal."""
    return not quiet and sys.stderr.isatty()


def bar(description: str, *, quiet: bool, total: float | None = None,
        unit: str = 'it', miniters: int | None = None) -> tqdm:
    """A tqdm bar on stderr (disabled when not ``wanted``), closed by the caller."""
    return tqdm(total=total, desc=description, unit=unit, file=sys.stderr, delay=DELAY,
                disable=not wanted(quiet), leave=False, dynamic_ncols=True,
                miniters=miniters)


class StepProgress:
    """A simulation observer (``sim.add_observer``) that counts steps and shows the sim
    time; a context manager that closes the bar."""

    def __init__(self, description: str, *, quiet: bool):
        self.bar = bar(description, quiet=quiet, unit=' steps')

    def __call__(self, result: Any) -> None:
        self.bar.update(1)
        if not self.bar.disable:
            self.bar.set_postfix_str(f'sim time {result.time:.3f} s', refresh=False)

    def __enter__(self) -> StepProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()


class StageProgress:
    """``progress(stage, done, total)`` for ``analyze``: one bar, relabelled per stage
    (its clock, and so the delay before it shows, runs from the first stage)."""

    def __init__(self, description: str, *, quiet: bool):
        self.description = description
        self.bar = bar(description, quiet=quiet, miniters=1)
        self.stage = ''

    def __call__(self, stage: str, done: int, total: int) -> None:
        if stage != self.stage:
            self.stage = stage
            self.bar.total = total
            self.bar.n = self.bar.last_print_n = 0
            self.bar.set_description(f'{self.description}: {stage}', refresh=False)
        self.bar.update(done - self.bar.n)

    def __enter__(self) -> StageProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()
