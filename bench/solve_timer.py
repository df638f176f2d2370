"""CPU time inside the 2D barrier model's compiled Newton solves, for the benchmarks
that set it beside the whole run's: the part of the barrier model's time that compiling
the Python around the solves would leave."""
from __future__ import annotations

import contextlib
import time


def _solve_entry():
    """(the owner, the name) of the compiled solve's entry from Python in the
    ``gripper_sim`` on ``sys.path``: ``barrier_newton.solve_from``, or in a checkout from
    before 2026-12-08 (``--baseline``) ``barrier_solve.CompiledSolve.run``."""
    from gripper_sim.core import barrier_newton
    if hasattr(barrier_newton, 'solve_from'):
        return barrier_newton, 'solve_from'
    from gripper_sim.core import barrier_solve
    return barrier_solve.CompiledSolve, 'run'


@contextlib.contextmanager
def solves_timed():
    """While open, the CPU time (``time.process_time``) inside the compiled 2D barrier
    Newton solves (``_solve_entry``: the solve alone, none of the step around it) of the
    ``gripper_sim`` on ``sys.path``: yields a one-item list that holds it (s; 0 where none
    ran)."""
    owner, name = _solve_entry()
    run = getattr(owner, name)
    inside = [0.0]

    def timed_run(*args, **kwargs):
        start = time.process_time()
        try:
            return run(*args, **kwargs)
        finally:
            inside[0] += time.process_time() - start
    setattr(owner, name, timed_run)
    try:
        yield inside
    finally:
        setattr(owner, name, run)
