"""The 2D barrier model's compiled Newton solve (``core.barrier_newton``, run by
``core.barrier_solve``; the default where it covers the solve:
``fast_solver.COMPILED_BARRIER_SOLVE``) against the interpreted route it replaces there:
the same positions to the last bit at every step, the same Newton iterations, the same
contact forces, and the same solver work (systems, factorisations, CG iterations), each
solve making its own Newton matrix as the interpreted route does
(``fast_solver.CARRY_NEWTON_MATRIX`` off); and what carrying the matrix from solve to
solve saves."""
import numpy as np
import pytest

from helpers import quasi_static_sim

from gripper_sim.configuration import load_config
from gripper_sim.core import fast_solver
from gripper_sim.core.simulation import Simulation
from gripper_sim.workflows.grasp import GraspSequence, run_grasp

RADIUS = 0.03


def _ring(approach, *overrides):
    sim = quasi_static_sim(RADIUS, 'fruit.nodes=64', 'contact.model=ipc', *overrides)
    sim.command_gap(2 * RADIUS - approach, speed=approach / 0.5)
    return sim


def _apple():
    """The default apple on the table (friction, gravity, bulk modulus: the pressure's
    rank-one term) squeezed to 2 N by the ipc model."""
    sim = Simulation(load_config(overrides=['contact.model=ipc', 'fruit.nodes=64',
                                            'gripper.initial_gap=0.0645']))
    sim.command_force(2.0, speed=0.01)
    return sim


def _solid_disk():
    """The 2D solid disk (neo-Hookean flesh) squeezed by the ipc model."""
    sim = quasi_static_sim(RADIUS, 'fruit.model=solid', 'contact.model=ipc')
    sim.command_gap(2 * RADIUS - 0.002, speed=0.004)
    return sim


def _trace(make, steps, compiled, monkeypatch):
    """(positions and contact forces of every step, Newton iterations, solver stats, work
    counters, the last grip force N) of a run."""
    monkeypatch.setattr(fast_solver, 'COMPILED_BARRIER_SOLVE', compiled)
    monkeypatch.setattr(fast_solver, 'CARRY_NEWTON_MATRIX', False)
    sim = make()
    assert sim.solver.compiled_solve_covers()
    positions, iterations = [], []
    for _ in range(steps):
        result = sim.step()
        positions.append(np.concatenate([sim.q.ravel(), sim.contact_forces.ravel()]))
        iterations.append(result.newton_iterations)
    return (positions, iterations, dict(sim.solver.stats), sim.solver.counts.copy(),
            result.grip_force)


@pytest.mark.parametrize('make,steps', [
    (lambda: _ring(0.005 * RADIUS, 'fruit.skin.youngs_modulus=1e7',
                   'fruit.skin.thickness=1e-3',
                   'fruit.pressure.turgor=0', 'fruit.pressure.bulk_modulus=0'), 120),
    (lambda: _ring(0.2 * RADIUS, 'fruit.skin.youngs_modulus=1e9',
                   'fruit.skin.thickness=1e-5',
                   'fruit.pressure.turgor=2e4', 'fruit.pressure.bulk_modulus=0'), 100),
    (_apple, 160), (_solid_disk, 60)], ids=['ring', 'membrane', 'apple', 'solid-disk'])
def test_compiled_solve_repeats_the_interpreted_one_to_the_bit(make, steps, monkeypatch):
    interpreted = _trace(make, steps, False, monkeypatch)
    compiled = _trace(make, steps, True, monkeypatch)
    assert compiled[1] == interpreted[1]
    assert compiled[2] == interpreted[2]
    np.testing.assert_array_equal(compiled[3], interpreted[3])
    for step, (a, b) in enumerate(zip(compiled[0], interpreted[0])):
        assert a.tobytes() == b.tobytes(), f'step {step}'
    assert interpreted[4] > 0.0  # the runs made contact


def _fin_ray_grasp(compiled, monkeypatch, carry=False):
    """(positions and contact forces of every step, Newton iterations, solver stats,
    outcome, work counters, the last step's grip force N and contact length m) of the 2D
    Fin Ray grasp-and-lift (two barriers: the fingers' self-contact and the fruit's with
    the soft fingers; the fingers' bases held by the filters)."""
    monkeypatch.setattr(fast_solver, 'COMPILED_BARRIER_SOLVE', compiled)
    monkeypatch.setattr(fast_solver, 'CARRY_NEWTON_MATRIX', carry)
    config = load_config(overrides=['gripper.finger.type=fin_ray'])
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
    sim = Simulation(config)
    assert sim.solver.compiled_solve_covers()
    states, iterations = [], []

    def on_step(result, phase):
        states.append(np.concatenate([sim.q.ravel(), sim.contact_forces.ravel()]))
        iterations.append(result.newton_iterations)
    summary = run_grasp(sim, GraspSequence(sim, 4.0, lift_height=0.01, hold_time=0.2),
                        on_step=on_step)
    return (states, iterations, dict(sim.solver.stats), summary['outcome'],
            sim.solver.counts.copy(), sim.last.grip_force, sim.last.deformation.contact_length,
            sim.solver.carry_newton_matrix)


def test_compiled_solve_repeats_the_fin_ray_grasp_to_the_bit(monkeypatch):
    interpreted = _fin_ray_grasp(False, monkeypatch)
    compiled = _fin_ray_grasp(True, monkeypatch)
    assert interpreted[3] == compiled[3] == 'held'
    assert compiled[1] == interpreted[1]
    assert compiled[2] == interpreted[2]
    assert len(compiled[0]) == len(interpreted[0])
    for step, (a, b) in enumerate(zip(compiled[0], interpreted[0])):
        assert a.tobytes() == b.tobytes(), f'step {step}'


def test_a_solve_starts_with_the_newton_matrix_the_last_one_kept(monkeypatch):
    """The default (``CARRY_NEWTON_MATRIX``): a compiled solve's first step is a chord
    step with the matrix the last solve kept, where it fits (the deformable fingers'
    solver). On the Fin Ray's grasp it saves most Hessian evaluations and matrices (468
    against 1252 and 463 against 1248), at a few more Newton systems, and ends at the
    same grip and contact length (within the Newton tolerance's reach: 1e-5
    relative)."""
    from gripper_sim.core import newton
    fresh = _fin_ray_grasp(True, monkeypatch)
    carried = _fin_ray_grasp(True, monkeypatch, carry=True)
    assert carried[7]  # the deformable fingers' solver carries it
    assert fresh[3] == carried[3] == 'held'
    assert carried[4][newton.C_HESSIAN_EVALS] < 0.5 * fresh[4][newton.C_HESSIAN_EVALS]
    assert carried[4][newton.C_FACTORS] < 0.5 * fresh[4][newton.C_FACTORS]
    assert carried[4][newton.C_DIRECTIONS] < 1.1 * fresh[4][newton.C_DIRECTIONS]
    assert carried[5] == pytest.approx(fresh[5], rel=1e-5)
    assert carried[6] == pytest.approx(fresh[6], rel=1e-5)


def test_a_kept_newton_matrix_serves_only_its_own_dt_and_filters(monkeypatch):
    """The matrix a solve kept serves the next solve only where it was made for that
    solve's dt (the inertia's M / dt^2 is in it; a halved step makes its own) and its
    filters' values (the prescribed nodes), and while it is younger than
    ``newton.MAX_FACTOR_AGE`` solves; never with carrying off."""
    from gripper_sim.core import barrier_newton as bn
    from gripper_sim.core import newton
    monkeypatch.setattr(fast_solver, 'CARRY_NEWTON_MATRIX', True)
    sim = _ring(0.005 * RADIUS)
    assert not sim.solver.carry_newton_matrix  # rigid faces: not by default
    sim.solver.carry_newton_matrix = True
    for _ in range(40):
        sim.step()
    compiled = sim.solver._compiled
    kept, filters, dt = compiled.kept, compiled.kept_filters.copy(), sim.dt
    assert compiled.flags[bn.F_KEPT] >= 0 and kept[bn.K_DT] == dt
    assert kept[bn.K_AGE] < newton.MAX_FACTOR_AGE
    assert bn._kept_fits(compiled.problem, kept, compiled.kept_filters, filters, dt)
    assert not bn._kept_fits(compiled.problem, kept, compiled.kept_filters, filters, 0.5 * dt)
    pinned = filters.copy()
    pinned[3] = 0.0  # a node held
    assert not bn._kept_fits(compiled.problem, kept, compiled.kept_filters, pinned, dt)
    old = kept.copy()
    old[bn.K_AGE] = newton.MAX_FACTOR_AGE
    assert not bn._kept_fits(compiled.problem, old, compiled.kept_filters, filters, dt)
    off = kept.copy()
    off[bn.K_CARRY] = 0.0
    assert not bn._kept_fits(compiled.problem, off, compiled.kept_filters, filters, dt)
    sim.reset()
    assert not bn._kept_fits(compiled.problem, kept, compiled.kept_filters, filters, dt)


def test_the_ring_solves_compiled_by_default_and_the_shared_mmm_route_interpreted(
        monkeypatch):
    """The default route: the ring's barrier solves go through the compiled solve; the
    modified mass method on the shared solver (no barrier energy) stays on the
    interpreted one."""
    routes = []
    compiled = fast_solver.PatternCachingSolver.compiled_arguments

    def spy(self, *args):
        arguments = compiled(self, *args)
        if arguments is not None:
            routes.append('compiled')
        return arguments
    monkeypatch.setattr(fast_solver.PatternCachingSolver, 'compiled_arguments', spy)
    sim = _ring(0.002)
    for _ in range(5):
        sim.step()
    assert routes
    routes.clear()
    shared = quasi_static_sim(RADIUS, 'fruit.nodes=64', fast=False)
    assert not shared.solver.compiled_solve_covers()
    shared.command_gap(2 * RADIUS - 0.001, speed=0.002)
    for _ in range(3):
        shared.step()
    assert shared.solver.stats['passes'] and routes == []
