"""Run a study on Dask: every design point x fruit, rows as they finish, resumable.

Each (design point, fruit) is one Dask task (``study_tasks.run_fruit``): the fruit's
window search (``workflows.window.window_search``, the same bisections as ``gripper-sim
window``) from its closed-form seeds, or with a 'force' axis one evaluation per grid
force. All fruits of all design points run in parallel over the cluster; each
fruit's evaluations become rows as its task returns. A task is given the rows already
stored for its fruit (same effective configuration, scenario, force, kind and code
version: ``case_key``) and does not compute them again: a study run again computes only
what is missing. A results directory holds one study (``check_results_directory``):
another study, or a changed definition of this one, is refused before anything is
written, so that no rows are mixed.

The cluster: a local one on this machine's cores by default (worker processes on
127.0.0.1, one thread each), or an existing one (``scheduler='tcp://HOST:8786'``).
A worker that dies mid-task has its task run again elsewhere (Dask reschedules it);
Ctrl-C, or SIGTERM (``kill``, a batch system's time limit), cancels what is running
and keeps every finished row.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import signal
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from tqdm import tqdm

from gripper_sim.errors import GripperSimError, Terminated
from gripper_sim.workflows.grasp import GraspEvaluation
from gripper_sim.workflows.population_window import (SampleWindow, grid_curve,
                                                     population_window)
from gripper_sim.workflows.study_results import RowStore, held_study
from gripper_sim.workflows.study_spec import Study
from gripper_sim.workflows.study_spec import FruitSetup
from gripper_sim.workflows.study_tasks import (answer_key, code_version, evaluation_of,
                                               run_fruit)
from gripper_sim.workflows.window import (lower_bound_limited_by, trial_of,
                                          upper_bound_limited_by)

#: seconds to wait for an existing scheduler before giving up (a refused address too:
#: distributed retries it until then; at 3 s a scheduler on a loaded 2-core machine
#: sometimes had not finished its handshake, which read as 'not a Dask scheduler')
CONNECT_TIMEOUT = 10.0
#: evaluations a fruit's window search takes, until measured in the run
EXPECTED_PER_CHAIN = 13


class StudyError(GripperSimError):
    """The study cannot run (cluster unreachable, workers on other code, ...)."""


@dataclass
class StudyRun:
    """What ``run_study`` did: rows computed now and reused, whether it was interrupted,
    and the summary (``summary.json``)."""

    computed: int
    reused: int
    #: stopped by Ctrl-C or SIGTERM (then ``terminated`` too) before every row was done
    interrupted: bool
    summary: dict
    rows: list = field(default_factory=list)
    #: s of wall time: starting the cluster, and running the evaluations
    startup_time: float = 0.0
    run_time: float = 0.0
    #: the stop was a SIGTERM
    terminated: bool = False


def config_hash(config) -> str:
    """16 hex digits of the effective configuration (sorted JSON)."""
    text = json.dumps(dict(config), sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def case_key(setup: FruitSetup, kind: str, force: float, code: str) -> str:
    """The row key: effective configuration, scenario, kind, force and code version."""
    text = json.dumps(dict(config=config_hash(setup.config),
                           scenario=dict(setup.scenario.values), kind=kind,
                           force=repr(float(force)), code=code), sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _connect_failure(err: Exception) -> str:
    """Why a Dask client could not connect, in one line.

    Refused, timed out, unknown host (``OSError``) or a malformed address
    (``ValueError``) say so themselves; anything else came from reading the answer of
    a server that is not a Dask scheduler (an HTTP server's reply read as a frame
    length makes numpy allocate exabytes: a ``MemoryError``).
    """
    if isinstance(err, (OSError, ValueError)) and str(err):
        return str(err).splitlines()[0]
    return (f'something answers there, but not as a Dask scheduler, or not within '
            f'{CONNECT_TIMEOUT:g} s: {type(err).__name__} reading its reply')


@contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None) -> Iterator:
    """A Dask client: on ``scheduler`` (an address), or on a new local cluster of
    ``workers`` processes (default: this machine's cores) on 127.0.0.1.

    Raises:
        StudyError: the scheduler cannot be reached within ``CONNECT_TIMEOUT`` s.
    """
    from distributed import Client, LocalCluster
    if scheduler:
        try:
            client = Client(scheduler, timeout=f'{CONNECT_TIMEOUT}s')
        except Exception as err:  # noqa: BLE001 - refused, timed out, not a Dask server...
            raise StudyError(f'cannot reach the Dask scheduler at {scheduler} '
                             f'({_connect_failure(err)}); '
                             'start one with `dask scheduler`, or leave --scheduler out '
                             'for a local cluster') from err
        try:
            yield client
        finally:
            client.close()
        return
    count = workers or os.cpu_count() or 1
    cluster = None
    try:
        with _interrupt_recorded() as interrupted:
            # the scheduler's HTTP server (health and metrics; no dashboard: dashboard
            # False) on a free loopback port: on 8787, its default, a second study or
            # any other cluster made it warn 'Port 8787 is already in use'
            cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                   host='127.0.0.1', dashboard_address='127.0.0.1:0',
                                   scheduler_kwargs=dict(dashboard=False),
                                   silence_logs=logging.ERROR, preload=[IGNORE_CTRL_C])
        if interrupted:
            raise _stop_error(interrupted)
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()


#: the local workers' preload (Python source, run as each worker starts): a terminal's
#: Ctrl-C reaches the whole process group, and the client, not the workers, stops the
#: study (cancels its tasks, keeps its rows, closes the cluster)
IGNORE_CTRL_C = '''import signal, threading
if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGINT, signal.SIG_IGN)
'''


def _note_missing_workers(client, scheduler: str) -> None:
    """Say on stderr when the scheduler has no workers yet: the study waits for them
    (workers may be jobs still queued), and should not look hung while it does."""
    if not client.scheduler_info().get('workers'):
        print(f'note: the Dask scheduler at {scheduler} has no workers yet; the study '
              f'waits for them (start some with `dask worker {scheduler}`; Ctrl-C stops)',
              file=sys.stderr, flush=True)


#: the signals that stop a study, each as Ctrl-C does (cancel, keep the finished rows)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _stop_error(held: list[int]) -> KeyboardInterrupt:
    """The exception of the stop signals ``held``: ``Terminated`` for a SIGTERM."""
    return Terminated() if signal.SIGTERM in held else KeyboardInterrupt()


@contextmanager
def _handled(handler, numbers: tuple = STOP_SIGNALS) -> Iterator[None]:
    """``handler(number, frame)`` on the signals ``numbers`` within the block, the
    previous handlers after it. Outside the main thread (no signals there) nothing
    changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = [signal.signal(number, handler) for number in numbers]
    try:
        yield
    finally:
        for number, handler_before in zip(numbers, previous):
            signal.signal(number, handler_before)


@contextmanager
def _interrupt_recorded() -> Iterator[list[int]]:
    """Record Ctrl-C or SIGTERM instead of raising it while a local cluster starts (a
    KeyboardInterrupt inside ``LocalCluster`` could leave worker processes behind);
    yields a list that holds the signal once one arrived, for the caller to raise
    (``_stop_error``) once it can close the cluster."""
    held: list[int] = []
    with _handled(lambda number, _frame: held.append(number)):
        yield held


@contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM (``kill``, a batch system's time limit) stops the study as Ctrl-C does,
    raising ``Terminated`` (a KeyboardInterrupt), instead of ending the process at once
    with finished rows still in the row buffer. Ctrl-C keeps Python's own handling (or
    none, where the study was started with SIGINT ignored, as a script's background
    job)."""
    def stop(_number, _frame):
        raise Terminated()
    with _handled(stop, (signal.SIGTERM,)):
        yield


class _Chain:
    """One (design point, fruit): its set-up and, once its task is back, its result
    (window search: (min, max) N; grid: the evaluations, one per force)."""

    def __init__(self, setup: FruitSetup):
        self.setup = setup
        self.error = ''
        self.result: Any = None
        self.done = False


class _Runner:
    """The client side of a study run (see the module docstring)."""

    def __init__(self, study: Study, store: RowStore, client, progress: bool,
                 local: bool = False):
        from distributed import as_completed
        self.study = study
        #: the workers are this machine's local cluster (they import the same files)
        self.local = local
        self.store = store
        self.client = client
        self.code = code_version()
        self.computed = 0
        self.reused = 0
        #: the case_keys of the rows this run's evaluations are: reused or computed
        self.used: set[str] = set()
        self.waiting: dict[str, tuple[Any, list[_Chain]]] = {}
        self.chains: list[_Chain] = []
        self.bar = tqdm(total=0, unit='eval', file=sys.stderr, disable=not progress,
                        dynamic_ncols=True, desc=study.name)
        self.queue = as_completed()
        self.by_config: dict[str, list[dict]] = {}
        for row in store.rows.values():
            self.by_config.setdefault(row['config_hash'], []).append(row)

    def start(self, setups: list[FruitSetup]) -> None:
        """Submit one task per (design point, fruit) set-up, with the rows already
        stored."""
        study = self.study
        per_fruit = len(study.forces) or EXPECTED_PER_CHAIN
        for setup in setups:
            chain = _Chain(setup)
            self.chains.append(chain)
            known = self._known(setup)
            self.reused += len(known)
            self.used.update(row['case_key'] for row in known.values())
            args = (dict(setup.config), setup.scenario, study.tolerance, study.forces)
            key = 'fruit-' + hashlib.sha256(json.dumps(
                [config_hash(setup.config), dict(setup.scenario.values), study.tolerance,
                 study.forces, self.code, sorted(known)], default=repr).encode()
            ).hexdigest()[:24]
            future = self.client.submit(run_fruit, *args, known, key=key, retries=2)
            if future.key not in self.waiting:
                self.waiting[future.key] = (future, [])
                self.queue.add(future)
            self.waiting[future.key][1].append(chain)
            self.bar.total += max(per_fruit - len(known), 0)
        self.bar.refresh()

    def _known(self, setup: FruitSetup) -> dict:
        """The stored outputs of this fruit's evaluations, by ``answer_key``."""
        known = {}
        for row in self.by_config.get(config_hash(setup.config), ()):
            if row['case_key'] == case_key(setup, row['kind'], row['force'], self.code):
                known[answer_key(row['kind'], row['force'])] = row
        return known

    def run(self) -> None:
        """Until every fruit is done (KeyboardInterrupt on Ctrl-C)."""
        finished = []
        try:
            for future in self.queue:
                _, chains = self.waiting.pop(future.key)
                try:
                    value, failure = future.result(), ''
                except Exception as err:  # noqa: BLE001 - a lost task: the fruit's error
                    value, failure = None, f'{type(err).__name__}: {err}'
                new = self._keep(chains[0].setup, value['new'] if value else [])
                if value is not None and value['error']:
                    value, failure = None, value['error']
                for chain in chains:
                    self._finish(chain, value, failure)
                finished.append(new)
                mean = float(np.mean(finished))
                left = sum(1 for c in self.chains if not c.done) * mean
                self.bar.total = int(self.computed + math.ceil(left))
                self.bar.update(new)
        finally:
            self.store.flush()
            self.bar.close()

    def cancel(self) -> None:
        """Cancel every task not yet back (Ctrl-C)."""
        for future, _ in self.waiting.values():
            future.cancel()
        self.bar.close()

    def _keep(self, setup: FruitSetup, new: list) -> int:
        """Store the fruit's new evaluations as rows; how many."""
        for kind, force, outputs in new:
            if outputs['code_version'] != self.code:
                raise StudyError(self._other_code(outputs['code_version']))
            key = case_key(setup, kind, force, self.code)
            self.used.add(key)
            if key not in self.store:
                self.store.add(self._row(setup, kind, force, key, outputs))
                self.computed += 1
        return len(new)

    def _other_code(self, version: str) -> str:
        """Why a worker's code ``version`` is not this client's: on the local cluster the
        same files changed after the client read them, else another installation."""
        if self.local:
            return (f"gripper_sim's sources changed while the study started (this client "
                    f'read {self.code}, a worker {version}): run it again once they are '
                    'no longer being edited')
        return (f'a worker runs other code ({version}) than this client ({self.code}): '
                'install the same gripper_sim on every worker')

    def _finish(self, chain: _Chain, value: dict | None, failure: str) -> None:
        chain.done = True
        if value is None:
            chain.error = failure
            chain.result = [] if self.study.forces else (None, None, None, None)
        elif self.study.forces:
            chain.result = [evaluation_of(self.store.get(case_key(chain.setup, 'hold', f,
                                                                  self.code)))
                            for f in self.study.forces]
        else:
            chain.result = tuple(value['result'])

    def _row(self, setup: FruitSetup, kind: str, force: float, key: str,
             outputs: dict) -> dict:
        study = self.study
        point = study.points[setup.point]
        row = dict(study=study.name, case_key=key, config_hash=config_hash(setup.config),
                   point=setup.point, sample=setup.sample, seed=study.population.seed,
                   kind=kind, package_version=self.code.split('+')[0])
        row.update({k: v for k, v in point.values.items()})
        row.update(setup.drawn)
        row.update({k: v for k, v in outputs.items() if k not in row})
        row['force'] = float(force)
        return row


def run_study(study: Study, out: str | os.PathLike, *, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True) -> StudyRun:
    """Run ``study``, its rows in ``out/rows`` (resuming what is there), then its summary.
    Every (design point, fruit) set-up is built before the cluster starts, and nothing
    is written before the cluster is reached.

    Raises:
        StudyError: ``out`` holds another study's results or those of a changed
            definition of this one (``check_results_directory``), the cluster cannot be
            reached, or runs other code.
        ConfigError: a sample of the population is invalid at a design point (before
            the cluster starts).
    """
    setups = study.setups(study.population.draw())
    identity = dict(study=study.name, definition=study.definition_hash())
    check_results_directory(out, identity)
    check_writable(out)
    start = time.perf_counter()
    terminated = False
    with _terminate_as_interrupt(), open_client(scheduler, workers) as client:
        started = time.perf_counter()
        store = RowStore(out)
        store.claim(identity)
        runner = _Runner(study, store, client, progress, local=not scheduler)
        try:
            runner.start(setups)
            if scheduler:
                _note_missing_workers(client, scheduler)
            runner.run()
            complete = True
        except KeyboardInterrupt as stop:  # while submitting, waiting for workers, running
            runner.cancel()
            complete, terminated = False, isinstance(stop, Terminated)
        finally:
            store.flush()
        finished = time.perf_counter()
    superseded = store.compact(keep=runner.used) if complete else 0
    summary = summarise(study, runner.chains, store, complete)
    summary.update(computed=runner.computed, reused=runner.reused, superseded=superseded,
                   scheduler=scheduler or f'local ({workers or os.cpu_count()} workers)')
    return StudyRun(computed=runner.computed, reused=runner.reused,
                    interrupted=not complete, summary=summary, rows=store.sorted_rows(),
                    startup_time=started - start, run_time=finished - started,
                    terminated=terminated)


def check_writable(out: str | os.PathLike) -> None:
    """Refuse a results directory that cannot be made or written, before the cluster
    starts (it took tens of seconds to find out): a file, or a directory (``out``, else
    its nearest existing parent) that takes no file, tried with a temporary file that
    leaves nothing behind.

    Raises:
        StudyError: naming the path and why.
    """
    path = Path(out)
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise StudyError(f"cannot write results in '{out}': '{existing}' is not a directory")
    try:
        tempfile.TemporaryFile(dir=existing).close()
    except OSError as err:
        raise StudyError(f"cannot write results in '{out}': '{existing}' takes no file "
                         f'({err.strerror or err})') from err


def check_results_directory(out: str | os.PathLike, identity: dict[str, str]) -> None:
    """Refuse to run the study of ``identity`` ({'study': name, 'definition': hash})
    into ``out`` when ``out`` holds the results of another study, or of another
    definition of it: its rows would be mixed with the new ones. Resuming the same
    study (same name and definition) passes; so do results written before directories
    recorded their definition, if they are of the same study.

    Raises:
        StudyError: ``out`` holds other results (the message says what to do).
    """
    held = held_study(out)
    if held is None:
        return
    if held['study'] != identity['study']:
        raise StudyError(f"{out} holds study '{held['study']}' (its rows would be mixed "
                         f"with those of '{identity['study']}'): give another --out, or "
                         f'remove {out}')
    if held.get('definition') not in (None, identity['definition']):
        raise StudyError(f"{out} holds study '{held['study']}' run from another definition "
                         '(its base, axes, population or tolerance changed since; the rows '
                         'would be mixed): give another --out, or remove '
                         f'{out} to run it anew')


def summarise(study: Study, chains: list[_Chain], store: RowStore, complete: bool) -> dict:
    """The study's summary: per design point the fruits' windows, the population window
    and the success curve (JSON-ready)."""
    points = []
    for point in study.points:
        own = [c for c in chains if c.setup.point == point.index]
        limit = float(own[0].setup.config['gripper.max_force']) if own else math.inf
        # a failed fruit has no window: not one that holds nowhere, nor one to leave out
        failed = [c for c in own if c.error]
        windows = _sample_windows(study, [c for c in own if not c.error])
        entry: dict[str, Any] = dict(index=point.index, label=point.label(),
                                     values=dict(point.values), max_force=limit,
                                     complete=all(c.done for c in own))
        if entry['complete'] and windows and not failed:
            entry['population'] = population_window(
                windows, limit, study.fraction, study.confidence,
                seed=study.population.seed)
            if study.forces:
                entry['population']['curve'] = _grid_success(study, own)
        entry['samples'] = [dict(sample=w.sample, min_force=w.min_force,
                                 max_force=_number(w.max_force),
                                 max_force_limited_by=w.max_force_limited_by,
                                 min_force_limited_by=w.min_force_limited_by)
                            for w in windows]
        entry['failed'] = [dict(sample=c.setup.sample, error=c.error) for c in failed]
        points.append(entry)
    rows = store.rows.values()
    return dict(study=study.name, description=study.description, source=study.source,
                method=study.method, axes={k: list(v) for k, v in study.axes.items()},
                population=dict(samples=study.population.samples,
                                seed=study.population.seed,
                                distributions={d.key: d.describe()
                                               for d in study.population.distributions}),
                fraction=study.fraction, confidence=study.confidence,
                tolerance=study.tolerance, code_version=code_version(),
                complete=complete, rows=len(store),
                errors=sum(1 for r in rows if r.get('error')),
                points=points)


def _number(value):
    return 'inf' if value is not None and math.isinf(value) else value


def _sample_windows(study: Study, chains: list[_Chain]) -> list[SampleWindow]:
    if not all(c.done for c in chains):
        return []
    if not study.forces:
        return [SampleWindow(c.setup.sample, *c.result) for c in chains]
    by_sample: dict[int, list[GraspEvaluation]] = {}
    for chain in chains:
        by_sample.setdefault(chain.setup.sample, []).extend(chain.result)
    windows = []
    for sample, evaluations in sorted(by_sample.items()):
        held = [e.force for e in evaluations if e.held]
        low = min(held) if held else None
        trials = [trial_of(e, 'bruise') for e in evaluations]
        safe = [t.force for t in trials if t.safe]
        high = max(safe) if safe else None
        windows.append(SampleWindow(
            sample, low, high, upper_bound_limited_by(high, trials),
            lower_bound_limited_by(low, [trial_of(e, 'hold') for e in evaluations])))
    return windows


def _grid_success(study: Study, chains: list[_Chain]) -> dict:
    forces = list(study.forces)
    samples = sorted({c.setup.sample for c in chains})
    success = np.zeros((len(samples), len(forces)), dtype=bool)
    for chain in chains:
        for evaluation in chain.result:
            success[samples.index(chain.setup.sample), forces.index(evaluation.force)] = (
                evaluation.held and not (evaluation.bruised or evaluation.crushed))
    return grid_curve(success, forces, study.confidence)


def write_summary(summary: dict, path: str | os.PathLike) -> None:
    Path(path).write_text(json.dumps(summary, indent=1) + '\n', encoding='utf-8')

