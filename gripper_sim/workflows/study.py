"""Run a study on Dask: every design point x fruit, rows as they finish, resumable.

Each (design point, fruit) is a chain: the fruit's window search
(``core.window.window_search``, the same bisections as ``gripper-sim window``),
started from its closed-form seeds (``core.window.estimates``, one task), or, with a
'force' axis, one evaluation per grid force. Every evaluation is one Dask task
(``study_tasks.run_case``); the client advances each chain as its answers arrive, so
all chains run in parallel over the cluster. A request whose row is already stored
(same effective configuration, scenario, force, kind and code version: ``case_key``)
is answered from the store: a study run again computes only what is missing.

The cluster: a local one on this machine's cores by default (worker processes on
127.0.0.1, one thread each), or an existing one (``scheduler='tcp://HOST:8786'``).
A worker that dies mid-task has its task run again elsewhere (Dask reschedules it);
Ctrl-C cancels what is running and keeps every finished row.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Generator, Iterator

import numpy as np
from tqdm import tqdm

from gripper_sim.core.grasp import GraspEvaluation
from gripper_sim.core.window import estimates, trial_of, window_search
from gripper_sim.errors import GripperSimError
from gripper_sim.workflows.population_window import (SampleWindow, grid_curve,
                                                     population_window)
from gripper_sim.workflows.study_results import RowStore
from gripper_sim.workflows.study_spec import Study
from gripper_sim.workflows.study_spec import Trial as TrialSetup
from gripper_sim.workflows.study_tasks import code_version, run_case

#: seconds to wait for an existing scheduler before giving up
CONNECT_TIMEOUT = 3.0
#: evaluations a fruit's window search takes, until measured in the run
EXPECTED_PER_CHAIN = 13
_EVALUATION_FIELDS = [f.name for f in fields(GraspEvaluation) if f.name not in ('summary',
                                                                              'failure')]


class StudyError(GripperSimError):
    """The study cannot run (cluster unreachable, workers on other code, ...)."""


@dataclass
class StudyRun:
    """What ``run_study`` did: rows computed now and reused, whether it was interrupted,
    and the summary (``summary.json``)."""

    computed: int
    reused: int
    interrupted: bool
    summary: dict
    rows: list = field(default_factory=list)
    #: s of wall time: starting the cluster, and running the evaluations
    startup_time: float = 0.0
    run_time: float = 0.0


def config_hash(config) -> str:
    """16 hex digits of the effective configuration (sorted JSON)."""
    text = json.dumps(dict(config), sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def case_key(setup: TrialSetup, kind: str, force: float, code: str) -> str:
    """The row key: effective configuration, scenario, kind, force and code version."""
    text = json.dumps(dict(config=config_hash(setup.config),
                           scenario=dict(setup.scenario.values), kind=kind,
                           force=repr(float(force)), code=code), sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


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
            reason = str(err).splitlines()[0] if str(err) else type(err).__name__
            raise StudyError(f'cannot reach the Dask scheduler at {scheduler} ({reason}); '
                             'start one with `dask scheduler`, or leave --scheduler out '
                             'for a local cluster') from err
        try:
            yield client
        finally:
            client.close()
        return
    count = workers or os.cpu_count() or 1
    # the worker processes start with Ctrl-C ignored: a terminal's SIGINT reaches the
    # whole process group, and this client, not the workers, stops the study cleanly
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
    try:
        cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                               host='127.0.0.1', dashboard_address=None,
                               silence_logs=logging.ERROR)
    finally:
        if main_thread:
            signal.signal(signal.SIGINT, previous)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


class _Chain:
    """One (design point, fruit): its set-up, its search generator and its answers."""

    def __init__(self, setup: TrialSetup, search: Generator | None, grid: bool = False):
        self.setup = setup
        self.search = search
        self.grid = grid
        self.error = ''
        self.evaluations = 0
        self.result: Any = None
        self.done = False


def _grid_search(forces) -> Generator:
    """A search that asks for one evaluation per force; returns the evaluations."""
    evaluations = []
    for force in forces:
        evaluations.append((yield 'hold', force))
    return evaluations


def _row_evaluation(row: dict) -> GraspEvaluation:
    return GraspEvaluation(**{name: row[name] for name in _EVALUATION_FIELDS})


class _Runner:
    """The client side of a study run (see the module docstring)."""

    def __init__(self, study: Study, store: RowStore, client, progress: bool):
        self.study = study
        self.store = store
        self.client = client
        self.code = code_version()
        self.computed = 0
        self.reused = 0
        self.waiting: dict[str, tuple[Any, list]] = {}
        self.chains: list[_Chain] = []
        self.finished_counts: list[int] = []
        self.bar = tqdm(total=0, unit='eval', file=sys.stderr, disable=not progress,
                        dynamic_ncols=True, desc=study.name)
        from distributed import as_completed
        self.queue = as_completed()

    # -------------------------------------------------------------- set-up
    def start(self, samples: list[dict[str, float]]) -> None:
        study = self.study
        for point in study.points:
            for index, drawn in enumerate(samples):
                setup = study.trial(point, index, drawn)
                if study.forces:
                    for force in study.forces:
                        chain = _Chain(setup, _grid_search([force]), grid=True)
                        self.chains.append(chain)
                        self._feed(chain, None)
                else:
                    chain = _Chain(setup, None)
                    self.chains.append(chain)
                    future = self.client.submit(estimates, dict(setup.config),
                                                key=f'seeds-{config_hash(setup.config)}',
                                                retries=2)
                    self._wait(future, chain, None)
        self._update_total()

    # -------------------------------------------------------------- driving
    def _wait(self, future, chain: _Chain, request) -> None:
        if future.key not in self.waiting:
            self.waiting[future.key] = (future, [])
            self.queue.add(future)
        self.waiting[future.key][1].append((chain, request))

    def _feed(self, chain: _Chain, answer) -> None:
        """Send ``answer`` to the chain's search; answer its next requests from the store
        until one must be computed (submitted) or the search ends."""
        while True:
            try:
                request = next(chain.search) if answer is None else chain.search.send(answer)
            except StopIteration as stop:
                chain.result, chain.done = stop.value, True
                self.finished_counts.append(chain.evaluations)
                return
            kind, force = request
            key = case_key(chain.setup, kind, force, self.code)
            row = self.store.get(key)
            chain.evaluations += 1
            if row is None:
                future = self.client.submit(run_case, dict(chain.setup.config),
                                            chain.setup.scenario, float(force), kind,
                                            key=f'grasp-{key}', retries=2)
                self._wait(future, chain, (kind, force, key))
                return
            self.reused += 1
            answer = self._verdict(chain, row, kind)

    def _row(self, setup: TrialSetup, kind: str, force: float, key: str,
             outputs: dict) -> dict:
        study = self.study
        point = study.points[setup.point]
        row = dict(study=study.name, case_key=key, config_hash=config_hash(setup.config),
                   point=setup.point, sample=setup.sample, seed=study.population.seed,
                   kind=kind, package_version=self.code.split('+')[0])
        row.update({k: v for k, v in point.values.items()})
        row.update(setup.drawn)
        row.update(outputs)
        row['force'] = float(force)
        return row

    def run(self) -> bool:
        """Until every chain is done; False if interrupted (Ctrl-C)."""
        try:
            for future in self.queue:
                _, waiters = self.waiting.pop(future.key)
                try:
                    value = future.result()
                    failure = None
                except Exception as err:  # noqa: BLE001 - a lost task is a row
                    value, failure = None, f'{type(err).__name__}: {err}'
                for chain, request in waiters:
                    self._answer(chain, request, value, failure)
                self._update_total()
        except KeyboardInterrupt:
            for future, _ in self.waiting.values():
                future.cancel()
            return False
        finally:
            self.store.flush()
            self.bar.close()
        return True

    def _answer(self, chain: _Chain, request, value, failure: str | None) -> None:
        if request is None:  # the window seeds
            if failure is not None:
                chain.result, chain.done = (None, None), True
                chain.error = failure
                return
            hold, bruise, _ = value
            chain.search = window_search(chain.setup.config, hold, bruise,
                                         self.study.tolerance)
            self._feed(chain, None)
            return
        kind, force, key = request
        if key not in self.store:
            outputs = value if failure is None else run_case_failure(force, failure)
            if outputs['code_version'] != self.code:
                raise StudyError(f"a worker runs other code ({outputs['code_version']}) "
                                 f'than this client ({self.code}): install the same '
                                 'gripper_sim on every worker')
            self.store.add(self._row(chain.setup, kind, force, key, outputs))
            self.computed += 1
            self.bar.update(1)
        self._feed(chain, self._verdict(chain, self.store.get(key), kind))

    @staticmethod
    def _verdict(chain: _Chain, row: dict, kind: str):
        """A window search is sent the window's ``Trial``, a grid the evaluation."""
        evaluation = _row_evaluation(row)
        return evaluation if chain.grid else trial_of(evaluation, kind)

    def _update_total(self) -> None:
        mean = (float(np.mean(self.finished_counts)) if self.finished_counts
                else 1 if self.study.forces else EXPECTED_PER_CHAIN)
        left = sum(max(1.0, mean - c.evaluations) for c in self.chains if not c.done)
        self.bar.total = int(self.computed + math.ceil(left))


def run_case_failure(force: float, message: str) -> dict:
    """The outputs of a case whose task was lost (its worker kept dying, ...)."""
    return dict(force=float(force), outcome='error', held=False, dropped=True,
                slipped=False, bruised=True, crushed=True, slip_distance=0.0,
                peak_grip_force=0.0, peak_compression=0.0, peak_contact_pressure=0.0,
                peak_damage_pressure=0.0, bruised_fraction=0.0, error=message,
                sim_time=0.0, steps=0, message='', cpu_time=0.0, worker=-1,
                code_version=code_version())


def run_study(study: Study, out: str | os.PathLike, *, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True) -> StudyRun:
    """Run ``study``, its rows in ``out/rows`` (resuming what is there), then its summary.

    Raises:
        StudyError: the cluster cannot be reached, or runs other code.
        ConfigError: a sample of the population is invalid.
    """
    samples = study.population.draw()
    store = RowStore(out)
    start = time.perf_counter()
    with open_client(scheduler, workers) as client:
        started = time.perf_counter()
        runner = _Runner(study, store, client, progress)
        try:
            runner.start(samples)
            complete = runner.run()
        finally:
            store.flush()
        finished = time.perf_counter()
    summary = summarise(study, runner.chains, store, complete)
    summary.update(computed=runner.computed, reused=runner.reused,
                   scheduler=scheduler or f'local ({workers or os.cpu_count()} workers)')
    if complete:
        store.compact()
    return StudyRun(computed=runner.computed, reused=runner.reused,
                    interrupted=not complete, summary=summary, rows=store.sorted_rows(),
                    startup_time=started - start, run_time=finished - started)


def summarise(study: Study, chains: list[_Chain], store: RowStore, complete: bool) -> dict:
    """The study's summary: per design point the fruits' windows, the population window
    and the success curve (JSON-ready)."""
    points = []
    for point in study.points:
        own = [c for c in chains if c.setup.point == point.index]
        limit = float(own[0].setup.config['gripper.max_force']) if own else math.inf
        windows = _sample_windows(study, own)
        entry: dict[str, Any] = dict(index=point.index, label=point.label(),
                                     values=dict(point.values), max_force=limit,
                                     complete=all(c.done for c in own))
        if entry['complete'] and windows:
            entry['population'] = population_window(
                windows, limit, study.fraction, study.confidence,
                seed=study.population.seed)
            if study.forces:
                entry['population']['curve'] = _grid_success(study, own)
        entry['samples'] = [dict(sample=w.sample, min_force=w.min_force,
                                 max_force=_number(w.max_force)) for w in windows]
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
        safe = [e.force for e in evaluations if not (e.bruised or e.crushed)]
        windows.append(SampleWindow(sample, min(held) if held else None,
                                    max(safe) if safe else None))
    return windows


def _grid_success(study: Study, chains: list[_Chain]) -> dict:
    forces = list(study.forces)
    samples = sorted({c.setup.sample for c in chains})
    success = np.zeros((len(samples), len(forces)), dtype=bool)
    for chain in chains:
        (evaluation,) = chain.result
        success[samples.index(chain.setup.sample), forces.index(evaluation.force)] = (
            evaluation.held and not (evaluation.bruised or evaluation.crushed))
    return grid_curve(success, forces, study.confidence)


def write_summary(summary: dict, path: str | os.PathLike) -> None:
    Path(path).write_text(json.dumps(summary, indent=1) + '\n', encoding='utf-8')

