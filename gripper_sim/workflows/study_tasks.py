"""What a Dask worker runs for a study: one grasp evaluation (the window seeds are
``core.window.estimates`` itself).

Plain module-level functions, so that a task carries only its arguments and a worker
imports gripper_sim (and loads the compiled kernels) once, not per task.
"""
from __future__ import annotations

import functools
import hashlib
import os
import time
import traceback
from pathlib import Path
from typing import Any, Mapping

import gripper_sim
from gripper_sim.core.scenario import Scenario
from gripper_sim.core.window import evaluate_grasp


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
    """Evaluate one grasp (``core.window.evaluate_grasp``); its outputs as a row.

    Any error (a solver failure, or anything else this case raises) is the row's
    ``error`` with outcome 'solver failed' or 'error': the study goes on.
    """
    start = time.process_time()
    try:
        outputs = evaluate_grasp(config, scenario, force, kind).row()
    except Exception as err:  # noqa: BLE001 - a case's failure is a row, not a failed study
        where = traceback.extract_tb(err.__traceback__)[-1]
        outputs = dict(force=float(force), outcome='error', held=False, dropped=True,
                       slipped=False, bruised=True, crushed=True, slip_distance=0.0,
                       peak_grip_force=0.0, peak_compression=0.0,
                       peak_contact_pressure=0.0, peak_damage_pressure=0.0,
                       bruised_fraction=0.0,
                       error=f'{type(err).__name__}: {err} ({Path(where.filename).name}:'
                             f'{where.lineno})',
                       sim_time=0.0, steps=0, message='')
    outputs.update(cpu_time=time.process_time() - start, worker=os.getpid(),
                   code_version=code_version())
    return outputs

