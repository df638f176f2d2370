"""Bisections run in this process, or on several with the trials and answers of one.

A bisection (``window.bisection``) is a generator that yields the force to try next and
is sent back a verdict there; what it asks after a list of verdicts depends on those
verdicts alone, so it is found by replaying them into a fresh generator (``_follow``).
``run_searches`` keeps up to ``workers`` trials running: first the force each search
needs next on its own path (the serial search's), then, on free workers, the forces it
would need after each verdict a trial it is still waiting for can give (breadth first:
one verdict ahead, then two, ...), the searches taking turns. A search reads only the
verdicts on its path, in its order, so its answer, its trials and their order are the
serial search's; a trial off the path (a look-ahead the verdict went against) runs to
its end and is counted in ``SearchRun.wasted``.

With two bisections (the window's hold and bruise searches, independent of each other)
two workers run one trial of each at a time; a third and fourth look one verdict ahead.
"""
from __future__ import annotations

import multiprocessing
import queue
import signal
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable, Generator

from gripper_sim.errors import GripperSimError

#: a trial request: (kind, force N)
Request = tuple[str, float]


@dataclass(frozen=True)
class Search:
    """One bisection of a parallel run.

    Attributes:
        kind: its trials' kind ('hold', 'bruise').
        bisection: makes a fresh generator of it (yields forces N, is sent verdicts,
            returns its answer).
        verdict: the verdict a trial (``window.Trial``) gives it.
        verdicts: the verdicts it can give (the look-ahead follows each).
    """

    kind: str
    bisection: Callable[[], Generator[float, Any, Any]]
    verdict: Callable[[Any], Any]
    verdicts: tuple = (True, False)


@dataclass
class SearchRun:
    """What ``run_searches`` found: each search's answer and the trials on its path (in
    the serial search's order, each force once), and how many trials ran off the paths."""

    answers: list
    paths: list
    wasted: int = 0


def force_key(force: float) -> float:
    """The key two requests of the same force share (as the serial window's cache)."""
    return round(force, 12)


@dataclass
class _Plan:
    """A search's state given the trials known: finished with ``answer``, or waiting
    for ``wanted`` (the force its path needs first, then its look-ahead); ``path`` the
    known trials on its path."""

    finished: bool = False
    answer: Any = None
    path: list = field(default_factory=list)
    wanted: list = field(default_factory=list)


def _follow(search: Search, verdicts: list, known: dict) -> tuple[list, bool, Any, list]:
    """Replay ``verdicts`` into a fresh generator of ``search`` (what it asks depends on
    them alone), then walk on through the trials ``known`` ({(kind, key): trial or an
    exception}); (verdicts, finished, its answer or the unknown force it asks, the known
    trials met after ``verdicts``). An exception met re-raises (the serial search would
    have stopped there)."""
    verdicts, met = list(verdicts), []
    bisect = search.bisection()
    try:
        value = next(bisect)
        for verdict in verdicts:
            value = bisect.send(verdict)
        while True:
            outcome = known.get((search.kind, force_key(value)))
            if outcome is None:
                return verdicts, False, value, met
            if isinstance(outcome, BaseException):
                raise outcome
            met.append(outcome)
            verdicts.append(search.verdict(outcome))
            value = bisect.send(verdicts[-1])
    except StopIteration as stop:
        return verdicts, True, stop.value, met


def _plan(search: Search, known: dict, look_ahead: int) -> _Plan:
    """The search's path through ``known`` and up to ``look_ahead`` forces beyond its
    first unknown one, breadth first over the verdicts still unknown."""
    verdicts, finished, value, met = _follow(search, [], known)
    path, seen = [], set()
    for trial in met:
        if force_key(trial.force) not in seen:
            seen.add(force_key(trial.force))
            path.append(trial)
    if finished:
        return _Plan(finished=True, answer=value, path=path)
    wanted, level = [value], [verdicts]
    while level and len(wanted) <= look_ahead:
        next_level = []
        for branch in level:
            for verdict in search.verdicts:
                try:
                    ahead, done, force, _ = _follow(search, branch + [verdict], known)
                except GripperSimError:  # a failed trial ends this branch
                    continue
                if not done and force_key(force) not in map(force_key, wanted):
                    wanted.append(force)
                    next_level.append(ahead)
        level = next_level
    return _Plan(path=path, wanted=wanted[:look_ahead + 1])


def run_searches(searches: list[Search], pool, workers: int,
                 progress: Callable[[Any], None] | None = None) -> SearchRun:
    """Run ``searches`` side by side on ``pool`` (``start(request)``, ``finished()`` ->
    (request, trial or exception); at most ``workers`` trials running), each search's
    trials and answer those of the serial search (see the module). ``progress`` is called
    with each trial once it is known to lie on its search's path, in path order."""
    if workers < 1:
        raise GripperSimError(f'workers must be at least 1, got {workers}')
    known: dict = {}
    running: dict = {}
    reported = [0] * len(searches)
    while True:
        plans = [_plan(s, known, workers) for s in searches]
        for i, plan in enumerate(plans):
            for trial in plan.path[reported[i]:]:
                if progress is not None:
                    progress(trial)
            reported[i] = len(plan.path)
        if all(plan.finished for plan in plans):
            break
        for request in _take_turns(searches, plans):
            if len(running) >= workers:
                break
            key = (request[0], force_key(request[1]))
            if key not in known and key not in running:
                running[key] = request
                pool.start(request)
        request, outcome = pool.finished()
        key = (request[0], force_key(request[1]))
        running.pop(key, None)
        known[key] = outcome
    on_paths = {(s.kind, force_key(t.force)) for s, plan in zip(searches, plans)
                for t in plan.path}
    wasted = sum(1 for key in known if key not in on_paths)
    return SearchRun([plan.answer for plan in plans], [plan.path for plan in plans], wasted)


def _take_turns(searches: list[Search], plans: list[_Plan]) -> list[Request]:
    """The searches' wanted forces as requests, the searches taking turns at each depth
    (every search's next force first)."""
    requests = []
    for depth in range(max(len(plan.wanted) for plan in plans)):
        for search, plan in zip(searches, plans):
            if depth < len(plan.wanted):
                requests.append((search.kind, plan.wanted[depth]))
    return requests


class WorkerFailure(GripperSimError):
    """A trial failed in a worker process with an error that is not the project's own
    (its traceback in the message)."""


def _ignore_interrupts() -> None:
    """A worker's start: Ctrl-C is the parent's to handle (it stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _call(job: Callable, args: tuple, request: Request):
    """Run in a worker: ``job(*args, request)``; an error comes back as an exception
    that pickles (the project's errors by their message)."""
    try:
        return job(*args, request)
    except GripperSimError as err:
        return GripperSimError(str(err))
    except Exception:  # noqa: BLE001 - reported in the parent with its traceback
        return WorkerFailure(f'a trial failed in a worker process:\n{traceback.format_exc()}')


class InlinePool:
    """Runs each started trial at once in this process: with one worker ``run_searches``
    is the serial search (the searches one after the other, nothing run ahead). The
    project's errors are handed back as outcomes; any other propagates at once."""

    def __init__(self, job: Callable, args: tuple):
        self._job, self._args = job, args
        self._done: list = []

    def start(self, request: Request) -> None:
        try:
            outcome = self._job(*self._args, request)
        except GripperSimError as err:
            outcome = err
        self._done.append((request, outcome))

    def finished(self) -> tuple[Request, Any]:
        return self._done.pop(0)

    def __enter__(self) -> 'InlinePool':
        return self

    def __exit__(self, *exc) -> None:
        pass


class ProcessPool:
    """Worker processes (started with 'spawn': no state shared with this process)
    running ``job(*args, request)`` for each ``start(request)``; ``finished`` waits for
    the next result. ``close`` stops them, trials still running included."""

    def __init__(self, workers: int, job: Callable, args: tuple):
        self._pool = multiprocessing.get_context('spawn').Pool(workers,
                                                              initializer=_ignore_interrupts)
        self._job, self._args = job, args
        self._done: queue.Queue = queue.Queue()

    def start(self, request: Request) -> None:
        def finished(outcome, request=request):
            self._done.put((request, outcome))

        def failed(err, request=request):  # the task itself did not run (e.g. a pickle)
            self._done.put((request, WorkerFailure(
                f'a trial could not run in a worker process: {err!r}')))
        self._pool.apply_async(_call, (self._job, self._args, request), callback=finished,
                               error_callback=failed)

    def finished(self) -> tuple[Request, Any]:
        return self._done.get()

    def close(self) -> None:
        self._pool.terminate()
        self._pool.join()

    def __enter__(self) -> 'ProcessPool':
        return self

    def __exit__(self, *exc) -> None:
        self.close()
