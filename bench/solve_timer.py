"""CPU time inside the 2D barrier model's compiled Newton solves, for the benchmarks
that set it beside the whole run's: the part of the barrier model's time that compiling
the Python around the solves would leave."""
from __future__ import annotations

import contextlib
import time


@contextlib.contextmanager
def solves_timed():
    """While open, the CPU time (``time.process_time``) inside the compiled 2D barrier
    Newton solves (``barrier_solve.CompiledSolve.run``, the solve alone, none of the step
    around it) of the ``gripper_sim`` on ``sys.path``: yields a one-item list that holds
    it (s; 0 where none ran)."""
    from gripper_sim.core import barrier_solve

    run = barrier_solve.CompiledSolve.run
    inside = [0.0]

    def timed_run(*args, **kwargs):
        start = time.process_time()
        try:
            return run(*args, **kwargs)
        finally:
            inside[0] += time.process_time() - start
    barrier_solve.CompiledSolve.run = timed_run
    try:
        yield inside
    finally:
        barrier_solve.CompiledSolve.run = run
