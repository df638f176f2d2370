"""What a Dask worker runs for a study: one fruit at one design point (``run_fruit``):
its window search, or its force grid, one grasp evaluation (``run_case``) per force.

A task per fruit, not per evaluation: a window search is a dozen evaluations of
~15 ms, and a Dask task costs the client, scheduler and worker several ms of CPU of
their own. Plain module-level functions, so that a task carries only its arguments and
a worker imports gripper_sim (and loads the compiled kernels) once, not per task.
"""
from __future__ import annotations

import functools
import hashlib
import os
import time
import traceback
from pathlib import Path
from dataclasses import fields
from typing import Any, Mapping, Sequence

import gripper_sim
from gripper_sim.workflows.grasp import GraspEvaluation
from gripper_sim.workflows.scenario import Scenario
from gripper_sim.workflows.window import (estimates, evaluate_grasp, run_search, trial_of,
                                     lower_bound_limited_by, upper_bound_limited_by,
                                     window_search)

#: the fields of a GraspEvaluation a row carries
EVALUATION_FIELDS = tuple(f.name for f in fields(GraspEvaluation)
                          if f.name not in ('summary', 'failure'))


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """The package version and a digest of its Python sources, e.g. '0.1.0+3f2a9c1e0b7d'."""
    root = Path(gripper_sim.__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob('*.py')):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return f'{gripper_sim.__version__}+{digest.hexdigest()[:12]}'


def run_case(config: Mapping[str, Any], scenario: Scenario, force: float,
             kind: str) -> dict[str, Any]:
    """Evaluate one grasp (``workflows.window.evaluate_grasp``); its outputs as a row.

    Any error (a solver failure, or anything else this case raises) is the row's
    ``error`` with outcome 'solver failed' or 'error': the study goes on.
    """
    start = time.process_time()
    try:
        outputs = evaluate_grasp(config, scenario, force, kind).row()
    except Exception as err:  # noqa: BLE001 - a case's failure is a row, not a failed study
        outputs = dict(force=float(force), outcome='error', held=False, dropped=True,
                       slipped=False, bruised=True, crushed=True, slip_distance=0.0,
                       peak_grip_force=0.0, peak_compression=0.0,
                       peak_jaw_pressure=0.0, peak_table_pressure=0.0,
                       peak_damage_pressure=0.0, bruised_at='',
                       bruised_fraction=0.0, error=error_text(err),
                       sim_time=0.0, steps=0, message='')
    outputs.update(cpu_time=time.process_time() - start, worker=os.getpid(),
                   code_version=code_version())
    return outputs


def error_text(err: Exception) -> str:
    """'Type: message (file.py:line)': an exception and where it was raised."""
    where = traceback.extract_tb(err.__traceback__)[-1]
    return f'{type(err).__name__}: {err} ({Path(where.filename).name}:{where.lineno})'


def evaluation_of(outputs: Mapping[str, Any]) -> GraspEvaluation:
    """The ``GraspEvaluation`` of a row's outputs."""
    return GraspEvaluation(**{name: outputs[name] for name in EVALUATION_FIELDS})


def answer_key(kind: str, force: float) -> tuple[str, str]:
    """How a fruit's known evaluations are looked up: (kind, repr of the force)."""
    return kind, repr(float(force))


def run_fruit(config: Mapping[str, Any], scenario: Scenario, tolerance: float,
              forces: Sequence[float], known: Mapping[tuple[str, str], dict]) -> dict:
    """One fruit at one design point.

    Without ``forces``: its window search (``workflows.window.window_search`` from the seeds
    of ``estimates``), returning ``result`` = (min_force, max_force, what limited
    max_force: ``window.upper_bound_limited_by``, why min_force is None:
    ``window.lower_bound_limited_by``). With ``forces``:
    one 'hold' evaluation per force, ``result`` None. An evaluation already in
    ``known`` (outputs by ``answer_key``, from a previous run) is not computed again.
    An exception of the search itself (not of a case: that is the case's row) is the
    fruit's ``error``, returned rather than raised: the task does not fail, so Dask
    neither logs its traceback nor runs it again, and the evaluations before it are kept.

    Returns:
        {'result': ... (None after an error), 'new': [(kind, force, outputs), ...] the
        evaluations computed, 'error': '' or ``error_text`` of the search's exception}.
    """
    answers = dict(known)
    new: list[tuple[str, float, dict]] = []

    def evaluation(request: tuple[str, float]) -> GraspEvaluation:
        kind, force = request
        key = answer_key(kind, force)
        if key not in answers:
            answers[key] = run_case(config, scenario, force, kind)
            new.append((kind, float(force), answers[key]))
        return evaluation_of(answers[key])

    try:
        result = _fruit_result(config, tolerance, forces, evaluation)
    except Exception as err:  # noqa: BLE001 - the fruit's failure, reported by the client
        return dict(result=None, new=new, error=error_text(err))
    return dict(result=result, new=new, error='')


def _fruit_result(config: Mapping[str, Any], tolerance: float, forces: Sequence[float],
                  evaluation) -> tuple | None:
    """``run_fruit``'s ``result``, its evaluations asked of ``evaluation``."""
    if forces:
        for force in forces:
            evaluation(('hold', force))
        return None
    hold, bruise, _ = estimates(config)
    trials = []

    def trial(request: tuple[str, float]):
        trials.append(trial_of(evaluation(request), request[0]))
        return trials[-1]

    low, high = run_search(window_search(config, hold, bruise, tolerance), trial)
    return (low, high, upper_bound_limited_by(high, trials),
            lower_bound_limited_by(low, trials))
