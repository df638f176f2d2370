"""Benchmark of the 2D physics core on a grasp-and-lift. Prints figures; asserts nothing.

Every set-up side by side in one run - the default fruit (shell model, 64 skin nodes)
and the solid model (a meshed disk of about 200 nodes), each with flat, arc and V-groove
fingers and with a soft pad on flat fingers: a grasp-and-lift (close to 3 N, settle,
lift 5 cm, hold 1 s) at the configured step on one core, in CPU time (this process's
``time.process_time``: what a quiet core gives; the machine's load average is printed):
CPU time per simulated second, the real-time factor (simulated seconds per CPU second),
mean Newton iterations per step, the route the step took, and where the time goes:

- assembly: energies, gradients and Hessians, and building the Newton matrix;
- solve: factorising the Newton matrix and solving with it: the shell's node-block band
  (with its rank-one pressure term), the solid's sparse LDL^T (``core.sparse_ldl``,
  minimum-degree order);
- contact: contact constraints, contact-set updates and the rest of a step's passes;
- measures: the step's outputs (StepResult, damage);
- other: gripper kinematics, the grasp state machine, Python glue.

Routes: 'kernel' = the whole step in one numba call (``core.fast``: shell, point and
solid fruits, flat, arc and V-groove fingers, with or without soft pads: every set-up
here); 'compiled' = the compiled energy kernels and the fixed-pattern Newton solver
(``core.fast_solver``) driven by the contact passes (``core.contact_passes``), which
``--set`` of a barrier contact model selects. On the kernel
route a step the kernel could not factorise (a non-symmetric contact filter, a guard: the
shared contact passes give symmetric ones) would be done by the compiled route; the table
counts those steps.
The grasp runs as ``pick`` and studies run it: ``run_grasp`` without a per-step callback,
so the steps at which the grasp decides nothing run many at a time in one compiled call
(``Simulation.advance``, ``core.multistep``: jaw drive, whole-step kernel, measures,
damage and the run's peaks inside numba); the 'watched' column gives the CPU time per
step with a callback that sees every step (the per-step route ``Simulation.step``, as
the ROS node and the recorders step).
Kernel route: glue, kernel and measures are timed with
perf_counter around each part; the kernel's own split comes from its work counters
(evaluations, factorisations, solves with a factor) times the cost of each operation
timed alone at the end state; one more step's kernel call is then repeated on its own
arguments (warm caches) and numba's dispatch of those arguments timed alone (a kernel
that does nothing).
Compiled route: fractions of a cProfile run applied to the plain run's CPU time.
Times are the best of ``--repeat`` runs.

``--baseline DIR`` compares with another checkout of the project (e.g. ``git worktree add
/tmp/base main``, its kernels compiled once): for each set-up, runs of this tree and of
DIR alternate, each in a fresh process (this script on the other tree, through the
GRIPPER_SIM_TREE environment variable), and the table gives both CPU times per step
(best of ``--repeat`` each), their ratio, and whether the two grasps ended alike
(outcome, steps, final gap within ``SAME_GAP`` = 1 nm). Usage::

    python bench/bench_core.py [--repeat N] [--hold S] [--setups shell,solid-vgroove,...]
        [--set key=value ...] [--baseline DIR]
"""
from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import sys
import time
from pathlib import Path

import numpy as np

#: the checkout whose gripper_sim is measured: this one, or GRIPPER_SIM_TREE (--baseline)
ROOT = Path(os.environ.get('GRIPPER_SIM_TREE') or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(ROOT))

from baseline import THIS_TREE, add_arguments, alternated, argument_problem  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core.simulation import Simulation  # noqa: E402
from gripper_sim.workflows.grasp import GraspSequence, run_grasp  # noqa: E402

FORCE, LIFT = 3.0, 0.05

#: set-up name -> configuration overrides
SETUPS = {
    'shell': ['fruit.model=shell'],
    'shell-arc': ['fruit.model=shell', 'gripper.finger.type=arc'],
    'shell-vgroove': ['fruit.model=shell', 'gripper.finger.type=vgroove'],
    'shell-pad': ['fruit.model=shell', 'gripper.finger.pad.enabled=true'],
    'solid': ['fruit.model=solid'],
    'solid-arc': ['fruit.model=solid', 'gripper.finger.type=arc'],
    'solid-vgroove': ['fruit.model=solid', 'gripper.finger.type=vgroove'],
    'solid-pad': ['fruit.model=solid', 'gripper.finger.pad.enabled=true'],
}


def grasp(sim: Simulation, hold: float, watch: bool = False) -> tuple:
    """One grasp-and-lift from the initial state: (wall s, cpu s, steps, Newton iterations,
    summary). ``watch``: a callback sees every step (the per-step route, as the node and
    the recorders step); else ``run_grasp`` runs the steps at which the grasp decides
    nothing in compiled calls (``Simulation.advance``), as ``pick`` and studies do."""
    sim.reset()
    sequence = GraspSequence(sim, FORCE, lift_height=LIFT, hold_time=hold)
    wall, cpu = time.perf_counter(), time.process_time()
    summary = run_grasp(sim, sequence, on_step=(lambda _result, _phase: None) if watch
                        else None)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return wall, cpu, sim.last.step, getattr(sim, 'newton_iterations', 0), summary


def _op_loops():
    """numba loops timing single kernel operations (compiled on first use)."""
    from numba import njit

    from gripper_sim.core import contact_kernels
    from gripper_sim.core import kernels as k

    @njit(cache=True)
    def evaluations(reps, hessian, q, q_n, v_n, dt, m2, alpha, beta, filters, frn, frt, frb,
                    frs, edges, spar, triples, bpar, ring, press, flesh, grav, pos, nbw):
        n2 = q.shape[0]
        band = k._newton_storage(n2 // 2, nbw, flesh)[0]
        grads = np.empty((4, n2))
        nopad, nopar = np.zeros(0, np.int64), np.zeros((0, k.PAD_SIZE))
        out = np.empty((6, n2))
        values = np.empty(4)
        acc = 0.0
        for _ in range(reps):
            phi, c = k._evaluate(q, q_n, v_n, dt, m2, alpha, beta, filters, frn, frt, frb,
                                 frs, frn.shape[0], edges, spar, triples, bpar, ring, press, flesh,
                                 grav, pos, hessian, out[0], out[1], grads, band, out[2],
                                 out[3], out[4], values, nopad, nopar)
            acc += phi
        return acc

    @njit(cache=True)
    def factorisations(reps, q, q_n, dt, m2, alpha, beta, filters, frn, frt, frb, frs, edges,
                       spar, triples, bpar, ring, press, flesh, grav, pos, nbw, solves):
        n2 = q.shape[0]
        n = n2 // 2
        band, ab, l_values, d_inv = k._newton_storage(n, nbw, flesh)
        grads = np.empty((4, n2))
        area = np.empty(n2)
        values = np.empty(4)
        k._energies(q, edges, spar, triples, bpar, ring, press, flesh, grav, pos, True, grads,
                    band, area, values)
        order = np.empty(n, np.int64)
        for i in range(n):
            order[pos[i]] = i
        nopad, nopar = np.zeros(0, np.int64), np.zeros((0, k.PAD_SIZE))
        x = np.ones(n2)
        y = np.ones(n2)
        # the rank-one term needs a second right-hand side (the shell's pressure)
        two = ring.shape[0] > 0
        ok = 0
        for rep in range(reps):
            if solves and rep > 0:
                k._newton_inverse(ab, l_values, d_inv, flesh, x, y, two)
            else:  # solves: on the factors of one factorisation
                ok += k._newton_factor(band, m2, dt, alpha, beta, filters, frn, frt, frb, frs,
                                       frn.shape[0], q, q_n, pos, order, 0.0, ab, nopad,
                                       nopar, flesh, l_values, d_inv)
        return ok

    @njit(cache=True)
    def contact_passes(reps, obstacle, mode, normal_force, bounce, secondary, secondary_bounce,
                       x_n, v_n, reaction, faces, surface, dt, v_corr, threshold, v_min):
        n = x_n.shape[0]
        start, filters = np.empty((n, 2)), np.empty((n, 2, 2))
        frn, frt = np.empty(n, np.int64), np.empty((n, 1, 2))
        frb, frs = np.empty(n), np.empty((n, 1))
        released, toggled = np.zeros(n, np.bool_), np.zeros(n, np.bool_)
        changed = 0
        for _ in range(reps):
            state = (obstacle.copy(), mode.copy(), normal_force.copy(), bounce.copy(),
                     secondary.copy(), secondary_bounce.copy())
            contact_kernels.constraints(state, faces, x_n, x_n, dt, v_corr, start, filters,
                                        frn, frt, frb, frs)
            changed += contact_kernels.update(state, faces, x_n, x_n, v_n, reaction, surface,
                                              dt, threshold, v_min, 0.0, released, toggled)
        return changed

    @njit(cache=True)
    def measures(reps, x, v, forces, obstacle, masses, surface, skin_edges, rest_segments,
                 face_par, jaw_origins, depth, edges, spar, triples, bpar, ring, press, flesh,
                 grav, d_face, d_rest, d_par, covered):
        n, ns = x.shape[0], surface.shape[0]
        normal, pressure, out = np.empty(n), np.empty(ns), np.empty(k.M_SIZE)
        values = np.zeros(4)
        d_pressure, patches = np.empty(ns), np.empty((ns, k.P_SIZE))
        groups = np.empty(d_face.shape[0], np.int64)
        for f in range(d_face.shape[0]):
            groups[f] = np.int64(d_face[f, 0])
        curvature = d_face[:, 1].copy()
        padded = d_face[:, 2].copy()
        total = 0.0
        for _ in range(reps):
            k.step_measures(x, v, forces, obstacle, masses, surface, skin_edges,
                            rest_segments, face_par, jaw_origins, depth, edges, spar, triples,
                            bpar, ring, press, flesh, grav, np.bool_(True), values, normal,
                            pressure, out)
            if d_rest.shape[0]:
                work = covered.copy()
                total += k.damage_update(x, normal, obstacle, surface, groups, curvature,
                                         padded, d_rest, d_par[0], d_par[1], d_par[2], work,
                                         d_pressure, patches)[1]
        return total

    return evaluations, factorisations, contact_passes, measures


def _best_time(fn, reps: int) -> float:
    """Seconds per call of fn(reps) / reps, best of 5."""
    fn(10)
    best = np.inf
    for _ in range(5):
        start = time.process_time()
        fn(reps)
        best = min(best, (time.process_time() - start) / reps)
    return best


def kernel_split(sim: Simulation) -> dict:
    """Seconds per operation at the current state: evaluations, factorisation, solve."""
    from gripper_sim.core import contact_kernels
    from gripper_sim.core import kernels as k
    evaluations, factorisations, contact_passes, measures = _op_loops()
    path = sim._fast
    n, dt = sim.fruit.n_nodes, sim.dt
    x_n, v_n = sim.q, sim.v
    c = sim.contacts
    start, filters = np.empty((n, 2)), np.empty((n, 2, 2))
    frn, frt = np.empty(n, np.int64), np.empty((n, 1, 2))
    frb, frs = np.empty(n), np.empty((n, 1))
    face_par, face_dyn = path.face_arrays()
    faces = k.contact_faces(face_par, face_dyn)
    n_fr = contact_kernels.constraints(c.arrays(), faces, x_n, x_n + dt * v_n, dt, 0.05, start,
                                       filters, frn, frt, frb, frs)
    frn, frt = frn[:n_fr].copy(), frt[:n_fr, 0].copy()
    frb, frs = frb[:n_fr].copy(), frs[:n_fr, 0].copy()
    model = path.model
    energy = (model['edges'], model['spar'], model['triples'], model['bpar'], model['ring'],
              model['press'], model['flesh'], path.gravity_grad, model['pos'], model['nbw'])
    q = x_n.ravel().copy()
    common = (q, x_n.ravel(), v_n.ravel(), dt, path.masses2, path.fpar[k.F_ALPHA],
              path.fpar[k.F_BETA], filters, frn, frt, frb, frs) + energy
    fac = (q, x_n.ravel(), dt, path.masses2, path.fpar[k.F_ALPHA], path.fpar[k.F_BETA],
           filters, frn, frt, frb, frs) + energy
    contact = (c.obstacle, c.mode, c.normal_force, c.bounce_speed, c.secondary,
               c.secondary_bounce, x_n, v_n, sim.contact_forces, faces, path.surface, dt,
               sim.config['contact.max_correction_speed'],
               sim.config['contact.release_threshold'], max(5 * sim.gravity.g * dt, 1e-3))
    damage = path.damage_inputs()
    grip = sim.gripper_state
    origins = np.array([[grip.x - 0.5 * grip.gap, grip.lift],
                        [grip.x + 0.5 * grip.gap, grip.lift]])
    meas = (x_n, v_n, sim.contact_forces, c.obstacle, path.masses, path.surface,
            path.skin_edges, path.rest_segments, face_par, origins, sim.fruit.depth,
            *energy[:8], *damage[:4])
    return dict(
        hessian_eval=_best_time(lambda r: evaluations(r, True, *common), 2000),
        eval=_best_time(lambda r: evaluations(r, False, *common), 2000),
        factor=_best_time(lambda r: factorisations(r, *fac, False), 2000),
        solve=_best_time(lambda r: factorisations(r, *fac, True), 2000),
        contact_pass=_best_time(lambda r: contact_passes(r, *contact), 2000),
        kernel_measures=_best_time(lambda r: measures(r, *meas), 2000))


def hot_kernel(args: tuple) -> tuple[float, float]:
    """Seconds per call of the substep kernel repeated on one step's arguments ``args``
    (warm caches; the contact state, arguments 2-7, copied each call as ``FastPath``
    does), and of numba's dispatch of the same arguments to a kernel that does nothing."""
    from numba import njit

    from gripper_sim.core import kernels as k

    @njit(cache=True)
    def nothing(*arguments):
        return len(arguments)

    args = tuple(a.copy() if isinstance(a, np.ndarray) else a for a in args)

    def repeated(reps):
        for _ in range(reps):
            call = list(args)
            for i in range(2, 8):
                call[i] = args[i].copy()
            k.substep(*call)

    def dispatched(reps):
        for _ in range(reps):
            nothing(*args)

    return _best_time(repeated, 200), _best_time(dispatched, 2000)


def profile_generic(sim: Simulation, hold: float) -> dict:
    """Fractions of CPU time in the compiled route's parts, from a cProfile run."""
    profiler = cProfile.Profile(time.process_time)
    profiler.enable()
    grasp(sim, hold)
    profiler.disable()
    stats = pstats.Stats(profiler).stats

    def cumulative(name: str, file_part: str) -> float:
        return sum(v[3] for key, v in stats.items()
                   if key[2] == name and file_part in key[0])

    total = cumulative('run_grasp', 'grasp.py')
    evaluate = cumulative('evaluate_fast', 'fast_solver.py')
    solve = cumulative('solve', 'fast_solver.py') - evaluate
    contact = (cumulative('contact_step', 'contact_passes.py')
               - cumulative('solve', 'fast_solver.py'))
    measures = cumulative('_measure', 'simulation.py')
    return dict(assembly=evaluate / total, solve=solve / total, contact=contact / total,
                measures=measures / total,
                other=1.0 - (evaluate + solve + contact + measures) / total)


def bench_model(name: str, overrides: list[str], repeat: int, hold: float) -> dict:
    config = load_config(overrides=SETUPS[name] + overrides)
    sim = Simulation(config)
    grasp(sim, 0.01)  # warm up: numba cache load, first-call costs
    if sim._fast is not None:
        sim._fast.fallbacks = 0
    runs = [grasp(sim, hold) for _ in range(repeat)]
    wall, cpu, steps, iterations, summary = min(runs, key=lambda r: r[1])
    watched = min((grasp(sim, hold, watch=True) for _ in range(repeat)), key=lambda r: r[1])
    sim_time = steps * sim.dt
    on_kernel = sim._fast is not None and sim._fast.applies()
    row = dict(model=name, nodes=sim.fruit.n_nodes, path='kernel' if on_kernel else 'compiled',
               fallbacks=sim._fast.fallbacks // repeat if on_kernel else 0,
               steps=steps, sim_time=sim_time, wall_per_sim=wall / sim_time,
               cpu_per_sim=cpu / sim_time, rtf=sim_time / wall, us_per_step=wall / steps * 1e6,
               iterations=iterations / steps, outcome=summary['outcome'],
               watched_us=watched[1] / watched[2] * 1e6)
    if on_kernel:
        path = sim._fast
        path.timing = True
        path.timers = dict.fromkeys(path.timers, 0.0)
        path.counts[:] = 0
        t_wall, t_cpu = grasp(sim, hold)[:2]
        path.timing = False
        # the timers are wall clock; on a shared machine the process also waits, so put
        # everything in CPU time (the op costs below are CPU time on a quiet loop)
        ratio = t_cpu / t_wall
        timers = {key: value * ratio for key, value in path.timers.items()}
        counts = path.counts.copy()
        ops = kernel_split(sim)
        from gripper_sim.core import kernels as k
        substep, last = k.substep, {}

        def spy(*args):  # the arguments of one more step, for ``hot_kernel``
            last['args'] = args
            return substep(*args)

        k.substep = spy
        try:
            sim.step()
        finally:
            k.substep = substep
        hot, dispatch = hot_kernel(last['args'])
        assembly = (counts[k.C_HESSIAN_EVALS] * ops['hessian_eval']
                    + counts[k.C_EVALS] * ops['eval'])
        # solves with a factor: one a Newton direction (a kept factor's too); a tree
        # without the counter solves once a factorisation
        directions = counts[getattr(k, 'C_DIRECTIONS', k.C_FACTORS)]
        solve = counts[k.C_FACTORS] * ops['factor'] + directions * ops['solve']
        contact = counts[k.C_SOLVES] * ops['contact_pass']
        substeps = counts[k.C_SUBSTEPS]
        kernel_measures = substeps * ops['kernel_measures']
        kernel = timers['kernel']
        parts = assembly + solve + contact + kernel_measures
        scale = min(1.0, kernel / parts)  # op costs timed in a loop: keep within the kernel
        assembly, solve, contact, kernel_measures = (
            assembly * scale, solve * scale, contact * scale, kernel_measures * scale)
        measures = timers['measures'] + kernel_measures
        row['split'] = dict(assembly=assembly / t_cpu, solve=solve / t_cpu,
                            contact=contact / t_cpu, measures=measures / t_cpu,
                            other=1.0 - (assembly + solve + contact + measures) / t_cpu)
        row['kernel_rest_us'] = (kernel - parts * scale) / steps * 1e6
        row['ops_us'] = {key: value * 1e6 for key, value in ops.items()}
        row['counts_per_step'] = dict(
            passes=counts[k.C_SOLVES] / steps, hessian_evals=counts[k.C_HESSIAN_EVALS] / steps,
            evals=counts[k.C_EVALS] / steps, factorisations=counts[k.C_FACTORS] / steps,
            solves=directions / steps)
        row['glue_us'] = timers['glue'] / steps * 1e6
        row['kernel_us'] = kernel / steps * 1e6
        row['hot_us'], row['dispatch_us'] = hot * 1e6, dispatch * 1e6
        row['n_args'] = len(last['args'])
    else:
        row['split'] = profile_generic(sim, hold)
    return row


#: m, final gaps this close count as the same end (two solvers meeting one Newton
#: tolerance differ by round-off, ~1e-11 m)
SAME_GAP = 1e-9


def plain_run(name: str, overrides: list[str], repeat: int, hold: float) -> dict:
    """CPU us per step (best of ``repeat`` grasps after a warm-up one) and how the grasp
    ended: outcome, steps, final gap (m, as repr)."""
    sim = Simulation(load_config(overrides=SETUPS[name] + overrides))
    grasp(sim, 0.01)
    runs = [grasp(sim, hold) for _ in range(repeat)]
    _wall, cpu, steps, _iterations, summary = min(runs, key=lambda r: r[1])
    return dict(us_per_step=cpu / steps * 1e6, dt=sim.dt, steps=steps,
                outcome=summary['outcome'], gap=repr(sim.gripper_state.gap),
                package=sys.modules['gripper_sim'].__file__)


def compare(baseline: Path, names: list[str], overrides: list[str], repeat: int,
            hold: float) -> None:
    """Print this tree's CPU time per step beside ``baseline``'s, runs alternated in fresh
    processes (see the module doc)."""
    trees = {'this': THIS_TREE, 'baseline': baseline.resolve()}
    best: dict = {}
    for name in names:
        arguments = ['--plain', '--repeat', '1', '--hold', str(hold), '--setups', name]
        for item in overrides:
            arguments += ['--set', item]
        outputs = alternated(Path(__file__).resolve(), baseline, arguments, repeat)
        for label, runs in outputs.items():
            rows = [run[name] for run in runs]
            for row in rows:
                if not Path(row['package']).is_relative_to(trees[label]):
                    raise RuntimeError(f'the run for {trees[label]} imported {row["package"]}')
            best[(name, label)] = min(rows, key=lambda row: row['us_per_step'])
    print(f'CPU us per step, best of {repeat} runs each, alternated: this tree '
          f'({trees["this"]}) and baseline ({trees["baseline"]}); load average '
          f'{os.getloadavg()[0]:.2f} at the end')
    print(f'{"set-up":<14} {"this":>8} {"baseline":>9} {"ratio":>6} {"RTF":>6} '
          f'{"RTF base":>8}  same end (outcome, steps, gap)   (RTF: real-time factor, CPU)')
    for name in names:
        mine, base = best[(name, 'this')], best[(name, 'baseline')]
        same = (mine['outcome'] == base['outcome'] and mine['steps'] == base['steps']
                and abs(float(mine['gap']) - float(base['gap'])) <= SAME_GAP)
        print(f'{name:<14} {mine["us_per_step"]:>8.1f} {base["us_per_step"]:>9.1f} '
              f'{mine["us_per_step"] / base["us_per_step"]:>6.2f} '
              f'{mine["dt"] * 1e6 / mine["us_per_step"]:>6.1f} '
              f'{base["dt"] * 1e6 / base["us_per_step"]:>8.1f}  '
              f'{"yes" if same else "NO"} ({mine["outcome"]}, {mine["steps"]}, {mine["gap"]}'
              + ('' if same else f'; baseline {base["outcome"]}, {base["steps"]}, '
                 f'{base["gap"]}') + ')')
    for label in trees:
        flat = {name: best[(name, label)]['us_per_step'] for name in names if '-' not in name}
        ratios = [f'{name} {best[(name, label)]["us_per_step"] / flat[name.split("-")[0]]:.2f}'
                  for name in names if '-' in name and name.split('-')[0] in flat]
        if ratios:
            print(f'x the flat fingers of the same fruit, {label}: {", ".join(ratios)}')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--repeat', type=int, default=3, help='runs per set-up (best CPU time)')
    parser.add_argument('--hold', type=float, default=1.0, help='hold time after lifting, s')
    parser.add_argument('--setups', default=','.join(SETUPS),
                        help=f'comma-separated, of: {", ".join(SETUPS)}')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help='configuration override for every set-up')
    add_arguments(parser, 'only the CPU time per step and the end of each grasp, as JSON '
                          '(what --baseline runs)')
    args = parser.parse_args(argv)
    names = args.setups.split(',')
    unknown = [name for name in names if name not in SETUPS]
    if unknown:
        print(f'error: unknown set-up {unknown[0]!r} (choose from {", ".join(SETUPS)})',
              file=sys.stderr)
        return 2
    problem = argument_problem(args)
    if problem:
        print(f'error: {problem}', file=sys.stderr)
        return 2
    if args.plain:
        print(json.dumps({name: plain_run(name, args.set, args.repeat, args.hold)
                          for name in names}))
        return 0
    if args.baseline is not None:
        compare(args.baseline, names, args.set, args.repeat, args.hold)
        return 0
    print(f'load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores')
    print(f'grasp-and-lift: close to {FORCE} N, lift {LIFT * 100:.0f} cm, hold {args.hold} s; '
          f'best of {args.repeat}')
    rows = [bench_model(name, args.set, args.repeat, args.hold)
            for name in args.setups.split(',')]
    print()
    print(f'{"set-up":<14} {"nodes":>5} {"route":<8} {"steps":>5} {"CPU us/step":>11} '
          f'{"CPU s/sim s":>11} {"CPU RTF":>7} {"wall RTF":>8} {"Newton it/step":>14} '
          f'{"off kernel":>10} {"watched us/step":>15} outcome')
    for r in rows:
        print(f'{r["model"]:<14} {r["nodes"]:>5} {r["path"]:<8} {r["steps"]:>5} '
              f'{r["cpu_per_sim"] * r["sim_time"] / r["steps"] * 1e6:>11.1f} '
              f'{r["cpu_per_sim"]:>11.4f} {1 / r["cpu_per_sim"]:>7.2f} {r["rtf"]:>8.2f} '
              f'{r["iterations"]:>14.2f} {r["fallbacks"]:>10} {r["watched_us"]:>15.1f} '
              f'{r["outcome"]}')
    print('(CPU RTF = simulated s per CPU s of this process: what a quiet core gives; wall '
          'RTF depends on the load; off kernel = steps of the kernel route done by the '
          'compiled route; watched = CPU us per step when a callback sees every step: the '
          'per-step route, as the node and the recorders step)')
    flat = {r['model'].split('-')[0]: r['cpu_per_sim'] for r in rows if '-' not in r['model']}
    for r in rows:
        fruit = r['model'].split('-')[0]
        if '-' in r['model'] and fruit in flat:
            print(f'{r["model"]}: {r["cpu_per_sim"] / flat[fruit]:.1f} x the CPU time of '
                  f'flat fingers ({fruit})')
    print()
    print('where the time goes (share of a grasp-and-lift, CPU us per step):')
    print(f'{"set-up":<14} {"assembly":>14} {"solve":>14} {"contact":>14} {"measures":>14} '
          f'{"other":>14}')
    for r in rows:
        cpu_us = r['cpu_per_sim'] * r['sim_time'] / r['steps'] * 1e6
        cells = ' '.join(
            f'{100 * r["split"][key]:>5.1f}% {cpu_us * r["split"][key]:>6.1f}us'
            for key in ('assembly', 'solve', 'contact', 'measures', 'other'))
        print(f'{r["model"]:<14} {cells}')
    for r in rows:
        if 'ops_us' in r:
            ops = ', '.join(f'{key} {value:.2f}' for key, value in r['ops_us'].items())
            per = ', '.join(f'{key} {value:.2f}' for key, value in r['counts_per_step'].items())
            print(f'\n{r["model"]} kernel operations, us each: {ops}')
            print(f'{r["model"]} per step: {per}; kernels {r["kernel_us"]:.1f} us, of '
                  f'which {r["kernel_rest_us"]:.1f} us the jaw drive, Newton bookkeeping and '
                  f'calls; Python glue around them {r["glue_us"]:.1f} us (steps run one by '
                  f'one)')
            print(f'{r["model"]} the last step\'s kernel call repeated (warm caches): '
                  f'{r["hot_us"]:.1f} us, of which {r["dispatch_us"]:.1f} us numba\'s dispatch '
                  f'of its {r["n_args"]} arguments; the rest of the whole kernel\'s time in the '
                  f'grasp: caches and branch predictors cold after the Python around each '
                  f'step, other processes on the core')
            print(f'{r["model"]} "other" = that glue and bookkeeping, the grasp state '
                  f'machine; "measures" = the kernel\'s measures and damage, the StepResult '
                  f'and damage objects of the steps the machine sees')
    return 0


if __name__ == '__main__':
    sys.exit(main())
