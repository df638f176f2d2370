"""Where the CPU time of a barrier-contact run goes: the 2D Fin Ray grasp-and-lift of
``bench_fin_ray.py`` (``fin_ray``), the pressurised ring squeeze of ``bench_barrier.py``
(``ring``) or its pick of the default apple with rigid fingers (``pick``; its steps
counted as Newton solves, its iterations as Newton directions). Prints figures; asserts
nothing.

One warm-up run (numba's caches loaded), then two timed runs (CPU time of this process,
``time.process_time``; the load average is printed):

- by part: each listed method or function is wrapped by a timer (inclusive times: a
  part contains the parts it calls; a few microseconds per call of overhead), with its
  calls, CPU time per call and its own time a step (outside the listed parts it
  calls: the work no listed part holds). Methods that a build no longer has are left
  out;
- compiled and not: every numba kernel bound in a ``gripper_sim`` module is wrapped,
  the time inside them (their call overhead included) against the rest (the Python
  around them, numpy, ipctk).

Usage::

    nice python bench/profile_barrier.py [fin_ray|ring|pick]
"""
from __future__ import annotations

import argparse
import collections
import functools
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))
sys.path.insert(0, str(ROOT / 'test'))

from numba.core.registry import CPUDispatcher  # noqa: E402

from gripper_sim.core import (barrier, facade, fast_solver, newton, simulation,  # noqa: E402
                              soft_fingers)

#: (label, owner, attribute) of the parts timed (a class's method or a module's function);
#: a label's indent shows where it is usually called (the own times follow the calls)
PARTS = (
    ('step', simulation.Simulation, 'step'),
    ('  measures (StepResult)', simulation.Simulation, '_measure'),
    ('    shared fields', facade.SimulationFacade, '_step_measures'),
    ('      barrier normal_forces', barrier.BarrierContact, 'normal_forces'),
    ('    deformation', simulation, 'deformation'),
    ('    tributary lengths', simulation, 'tributary_lengths'),
    ('    damage', simulation.Simulation, 'assess_damage'),
    ('  gripper after the step', facade.SimulationFacade, 'gripper_after'),
    ('  faces at the gripper', facade.SimulationFacade, 'faces_at'),
    ('  soft step (fruit and fingers)', facade.SimulationFacade, '_substep_soft'),
    ('    base targets', soft_fingers.SoftFingers, 'base_targets'),
    ('    barrier step', facade, 'soft_body_step'),
    ('    barrier step', facade, 'barrier_step'),
    ('      Newton solve', fast_solver.PatternCachingSolver, 'solve'),
    ('        evaluation with Hessian', fast_solver.PatternCachingSolver, 'evaluate_fast'),
    ('        linear solve', fast_solver.PatternCachingSolver, 'linear_solve'),
    ('        barrier evaluate_into', barrier.BarrierContact, 'evaluate_into'),
    ('        barrier max_step (CCD)', barrier.BarrierContact, 'max_step'),
    ('      barrier begin_step', barrier.BarrierContact, 'begin_step'),
    ('        face geometry and corners', barrier.BarrierContact, '_face_geometry'),
    ('        start candidates', barrier.BarrierContact, '_start_candidates'),
    ('        lagged friction', barrier.BarrierContact, '_lagged_friction'),
    ('        quiet region', barrier.BarrierContact, '_quiet_region'),
    ('      barrier pushed_starts', barrier.BarrierContact, 'pushed_starts'),
    ('      barrier reachable', barrier.BarrierContact, 'reachable'),
    ('      barrier partners', barrier.BarrierContact, 'partners'),
    ('      barrier contact_forces', barrier.BarrierContact, 'contact_forces'),
    ('      barrier holders', barrier.BarrierContact, 'holders'),
    ('  fingers: contact sticking (on read)', simulation.Simulation, '_fingers_sticking'),
    ('    fingers: jaw forces', simulation.Simulation, '_finger_jaw_forces'),
    ('  fingers: jaw wrenches', simulation.Simulation, '_finger_wrenches'),
    ('  fingers: result', soft_fingers.SoftFingers, 'result'),
)


#: the keys of the timed calls under way, innermost last (``_timed``)
_open: list = []


def _timed(function, label, times, calls, split=None, nested=None):
    """``function`` wrapped: its CPU time added to ``times[label]``, its calls counted, and
    (with ``nested``) its time added to ``nested[key]`` of the timed call it runs in."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        key = label
        if split is not None:
            key = split(label, args, kwargs)
        _open.append(key)
        start = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            elapsed = time.process_time() - start
            times[key] += elapsed
            calls[key] += 1
            _open.pop()
            if nested is not None and _open:
                nested[_open[-1]] += elapsed
    return wrapper


def _hessian_or_not(label, args, kwargs):
    hessian = kwargs.get('hessian', args[-1] if len(args) > 6 else True)
    return label if hessian else label.replace('with Hessian', 'gradient only')


def _self_contact_or_not(label, args, kwargs):
    return label + (' [self-contact]' if args[0].self_contact else '')


def wrap_parts(times, calls, nested) -> None:
    """Wrap the methods of ``PARTS`` that this build has; ``nested[key]``: the time of the
    timed parts called inside each part."""
    for label, owner, name in PARTS:
        function = getattr(owner, name, None)
        if function is None:
            continue
        split = (_hessian_or_not if name == 'evaluate_fast' else
                 _self_contact_or_not if owner is barrier.BarrierContact else None)
        setattr(owner, name, _timed(function, label, times, calls, split, nested))


def wrap_kernels(times, calls, nested=None) -> None:
    """Wrap every numba kernel bound in a loaded ``gripper_sim`` module (one timer each,
    under the label 'compiled kernels')."""
    wrappers = {}
    for name, module in list(sys.modules.items()):
        if not name.startswith('gripper_sim') or module is None:
            continue
        for attribute, value in list(vars(module).items()):
            if isinstance(value, CPUDispatcher):
                if id(value) not in wrappers:
                    wrappers[id(value)] = _timed(value, 'compiled kernels', times, calls)
                setattr(module, attribute, wrappers[id(value)])


def _in_order(times) -> list:
    """The labels timed, in the order of ``PARTS`` (each with its variants)."""
    order = list(dict.fromkeys(label for label, _, _ in PARTS))
    rank = {label: k for k, label in enumerate(order)}

    return sorted(times, key=lambda label: (rank.get(_base(label), len(order)), label))


def _base(label: str) -> str:
    """A timed label without its variant (``_hessian_or_not``, ``_self_contact_or_not``)."""
    return label.replace(' [self-contact]', '').replace('gradient only', 'with Hessian')


def run(case: str):
    """One run of ``case``; (steps, Newton iterations)."""
    if case == 'ring':
        from bench_barrier import membrane, timed
        iterations = timed(membrane, 'ipc')[1]
        return 150, iterations
    if case == 'pick':
        from helpers import pick
        sim, _ = pick(1.2, overrides=['contact.model=ipc'])
        return sim.solver.counts[newton.C_SOLVES], sim.solver.counts[newton.C_DIRECTIONS]
    from bench_soft_fingers import grasp
    figures = grasp('fin_ray', 4.0)
    return figures['steps'], figures['newton']


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('case', nargs='?', default='fin_ray', choices=('fin_ray', 'ring', 'pick'))
    args = parser.parse_args(argv)
    run(args.case)
    for wrap in (wrap_parts, wrap_kernels):
        times, calls = collections.defaultdict(float), collections.Counter()
        nested = collections.defaultdict(float)
        wrap(times, calls, nested)
        start = time.process_time()
        steps, iterations = run(args.case)
        total = time.process_time() - start
        print(f'{args.case}: load average {os.getloadavg()[0]:.2f}; {total:.3f} CPU s, '
              f'{steps} steps, {iterations} Newton iterations')
        if wrap is wrap_parts:
            print(f'{"part":44s} {"CPU s":>7s} {"%":>7s} {"calls":>7s} {"us a call":>10s} '
                  f'{"own us a step":>14s}')
        for label in _in_order(times):
            seconds = times[label]
            own = ('' if wrap is wrap_kernels else
                   f'{1e6 * (seconds - nested[label]) / steps:14.1f}')
            print(f'{label:44s} {seconds:7.3f} {100 * seconds / total:7.1f} '
                  f'{calls[label]:7d} {1e6 * seconds / calls[label]:10.1f} {own}')
        if wrap is wrap_kernels:
            rest = total - times['compiled kernels']
            print(f'{"the rest (Python, numpy, ipctk)":44s} {rest:7.3f} '
                  f'{100 * rest / total:7.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
