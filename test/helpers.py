"""Shared set-ups of the mechanics tests (also used by bench/validation_report.py)."""
import time

import numpy as np

from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import GraspSequence, evaluate, run_grasp
from gripper_sim.workflows.scenario import load_scenario, run_scenario, scenario_config
from gripper_sim.workflows.window import bisection, run_search

#: quasi-static settings: light fruit, mass damping, large step, no gravity, no table
QUASI_STATIC = ['world.gravity=0', 'world.table=false', 'fruit.density=50',
                'fruit.damping.mass=20', 'sim.dt=0.01', 'fruit.depth=0.01']

RING_COEFFICIENT = np.pi / 4 - 2 / np.pi  # 0.14878 (Roark; validation.md section 1)
RESTITUTION = 0.8


def quasi_static_sim(radius: float, *overrides: str, fast: bool | None = None) -> Simulation:
    config = load_config(overrides=QUASI_STATIC + [
        f'fruit.shape.diameter={2 * radius}', f'gripper.initial_gap={2 * radius + 1e-4}',
        *overrides])
    return Simulation(config, fast=fast)


def hollow_ring_error(radius, skin_modulus, thickness, nodes, deflection_ratio=0.005):
    """Relative error of the ring's compression against 0.14878 P R^3 / EI."""
    sim = quasi_static_sim(radius, f'fruit.skin.youngs_modulus={skin_modulus}',
                           f'fruit.skin.thickness={thickness}', f'fruit.nodes={nodes}',
                           'fruit.pressure.turgor=0', 'fruit.pressure.bulk_modulus=0')
    dv = deflection_ratio * radius
    sim.command_gap(2 * radius - dv, speed=dv / 0.5)
    result = sim.run(3.0)
    load = result.grip_force
    assert load > 0
    predicted = RING_COEFFICIENT * load * radius ** 3 / sim.fruit.bending_stiffness
    return result.deformation.compression / predicted - 1.0


def membrane(approach_ratio, nodes=256, radius=0.03, depth=0.01):
    """(grip force, pressure x contact length per jaw x depth, contact length per jaw)."""
    sim = quasi_static_sim(radius, 'fruit.skin.youngs_modulus=1e9', 'fruit.skin.thickness=1e-5',
                           f'fruit.nodes={nodes}', 'fruit.pressure.turgor=2e4',
                           'fruit.pressure.bulk_modulus=0')
    approach = approach_ratio * radius
    sim.command_gap(2 * radius - 2 * approach, speed=2 * approach / 0.5)
    result = sim.run(3.0)
    pressure = sim.fruit.pressure.pressure(result.positions.ravel())
    contact_per_jaw = result.deformation.contact_length / 2
    return result.grip_force, pressure * contact_per_jaw * depth, contact_per_jaw


def hertz_half_widths(force, nodes=512, radius=0.03, modulus=1e6, poisson=0.3, depth=0.01):
    """(measured contact half-width, Hertz half-width sqrt(4 F' R / (pi E*))), m."""
    sim = quasi_static_sim(radius, 'fruit.model=solid', 'fruit.skin.enabled=false',
                           f'fruit.nodes={nodes}', f'fruit.flesh.youngs_modulus={modulus}',
                           f'fruit.flesh.poisson_ratio={poisson}')
    sim.command_force(force, speed=0.004)
    result = sim.run(1.5)
    assert abs(result.grip_force / force - 1) < 1e-3
    plane_strain_modulus = modulus / (1 - poisson ** 2)
    hertz = np.sqrt(4 * result.grip_force / depth * radius / (np.pi * plane_strain_modulus))
    return result.deformation.contact_length / 4, hertz  # two jaws, full width each


def bouncing_node(dt):
    """The seed's bouncing node: dropped from 1 m, moving sideways between walls."""
    config = load_config(overrides=[
        'fruit.model=point', f'sim.dt={dt}', f'contact.restitution={RESTITUTION}',
        'fruit.initial_height=1.0', 'gripper.initial_lift=5', 'world.walls=true',
        'world.wall_half_width=0.3', 'fruit.initial_velocity.x=0.5',
        'contact.table.static_friction=0', 'contact.table.kinetic_friction=0'])
    return Simulation(config)


def bounce_apex_ratios(dt, count=4):
    """Ratios of successive apex heights of the bouncing node."""
    sim = bouncing_node(dt)
    z = np.array([sim.step().positions[0, 1] for _ in range(int(6.0 / dt))])
    inner = z[1:-1]
    apex = inner[(inner > z[:-2]) & (inner >= z[2:]) & (inner > 0.01)]
    return apex[1:count + 1] / apex[:count]


def pick(ratio, mu=0.5, lift=0.02, hold=1.0, overrides=()):
    """Grip so that 2 mu N = ratio m g, lift and hold; (sim, summary)."""
    config = load_config(overrides=[f'contact.jaw.static_friction={mu}',
                                    f'contact.jaw.kinetic_friction={mu}', *overrides])
    sim = Simulation(config)
    weight = sim.fruit.total_mass * config['world.gravity']
    force = ratio * weight / (2 * mu)
    sequence = GraspSequence(sim, force, lift_height=lift, hold_time=hold)
    return sim, run_grasp(sim, sequence)


def lift_newton_iterations(config, carried: bool, monkeypatch):
    """(Newton iterations of the lift, the simulation after it) of the fruit of
    ``config`` gripped at 4 N and lifted 1 cm, its barrier steps predicted carried with
    the gripper where the jaws hold it (``carried``: the build's) or not
    (``SimulationFacade._predicted_velocities`` patched to None)."""
    from gripper_sim.core.facade import SimulationFacade
    if not carried:
        monkeypatch.setattr(SimulationFacade, '_predicted_velocities',
                            lambda self, *args, **kwargs: None)
    sim = make_simulation(config)
    lift = []
    run_grasp(sim, GraspSequence(sim, 4.0, lift_height=0.01, hold_time=0.0),
              on_step=lambda result, phase: lift.append(result.newton_iterations)
              if phase == 'lifting' else None)
    monkeypatch.undo()
    return sum(lift), sim


def hold_minimum(config) -> float:
    """N, the grip force m g / (2 mu_s) at which jaw friction just carries the fruit."""
    sim = make_simulation(config)
    return (sim.fruit.total_mass * config['world.gravity']
            / (2 * config['contact.jaw.static_friction']))


def lift_hold_minimum(config) -> float:
    """N, m (g + a) / (2 mu_k), a = ``gripper.lift_acceleration``: the grip force at which
    kinetic jaw friction carries the fruit through the lift's acceleration (README,
    *Grasp window*)."""
    sim = make_simulation(config)
    return (sim.fruit.total_mass * (config['world.gravity'] + config['gripper.lift_acceleration'])
            / (2 * config['contact.jaw.kinetic_friction']))


def hold_threshold(config, low, high, lift=0.02, hold=0.2, tolerance=0.005):
    """The smallest commanded grip force (N) at which a pick (close, lift ``lift`` m, hold
    ``hold`` s) holds: carried to the end, not dropped, less than ``window.max_slip`` of
    slip (``GraspEvaluation.held``). Found by the grasp window's bisection from the bracket
    [low, high] N (widened as needed) to ``tolerance`` (relative). Returns (threshold N,
    the largest force tried that did not hold N, the trials' ``GraspEvaluation`` list)."""
    trials = []

    def held(force):
        sim = make_simulation(config)
        sequence = GraspSequence(sim, force, lift_height=lift, hold_time=hold)
        trials.append(evaluate(sim, sequence, force))
        return trials[-1].held
    threshold = run_search(bisection(low, high, config['gripper.max_force'], tolerance,
                                     want_smallest=True), held)
    below = max((t.force for t in trials if not t.held), default=0.0)
    return threshold, below, trials


def traced_pick(config, force, lift=0.05, hold=1.0):
    """Pick at ``force`` (N): close, lift ``lift`` m, hold ``hold`` s. Returns a dict:
    outcome, slip (m, the contacts' slide), drop (m, the centroid's largest drop relative
    to the jaws), peak (N, peak grip force), lift_min (N, the lowest grip force
    from the start of the lift to the end of the hold), solves (mean solves per step) and
    cpu (s, process time)."""
    start = time.process_time()
    sim = make_simulation(config)
    sequence = GraspSequence(sim, force, lift_height=lift, hold_time=hold)
    lifted = []
    summary = run_grasp(sim, sequence, on_step=lambda r, phase: lifted.append(r.grip_force)
                        if phase in ('lifting', 'holding') else None)
    return dict(outcome=summary['outcome'], slip=summary['slip_distance'],
                drop=summary['centroid_drop'], peak=summary['peak_grip_force'], lift_min=min(lifted, default=0.0),
                solves=sim.gap_solves / max(sim.last.step, 1),
                cpu=time.process_time() - start)


def converged(rows: list[dict]) -> tuple[bool, bool, bool]:
    """Of ``traced_pick`` rows, finest dt last: (the same outcome at every dt, every slip
    within max(0.2 mm, 20 %) of the finest dt's, every peak grip force within 2 %)."""
    finest = rows[-1]
    same = all(r['outcome'] == finest['outcome'] for r in rows)
    slip = all(abs(r['slip'] - finest['slip']) <= max(2e-4, 0.2 * finest['slip'])
               for r in rows)
    peak = all(abs(r['peak'] - finest['peak']) <= 0.02 * finest['peak'] for r in rows)
    return same, slip, peak


def pick_and_place_forces(fruit, force, *overrides):
    """Run the pick_and_place scenario in force mode at ``force`` (N). Returns (summary,
    peak grip force per phase (N), lowest grip force during the lift (N), cpu s)."""
    start = time.process_time()
    scenario = load_scenario('pick_and_place').with_values(close__mode='force',
                                                           close__force=force)
    sim = make_simulation(scenario_config(scenario, fruit=fruit, overrides=list(overrides)))
    peaks, lift = {}, []

    def on_step(result, phase):
        peaks[phase] = max(peaks.get(phase, 0.0), result.grip_force)
        if phase == 'lift':
            lift.append(result.grip_force)
    summary = run_scenario(sim, scenario, on_step=on_step)
    return summary, peaks, min(lift, default=0.0), time.process_time() - start


def hertz_sphere_errors(subdivisions, refinement, order=2, dt=0.05):
    """Solid sphere between two plates, quasi-static (large dt, light, damped).

    The jaws keep their default friction (sticking contact nodes): frictionless plates
    leave the sphere free to turn about x, which costs many more Newton iterations,
    and change the Hertz force by a few per cent only.

    Returns ({D/R: (force error, contact radius error)}, deepest penetration of a skin
    node into a plate over the approach) against Hertz:
    F = (sqrt(2)/3) E* sqrt(R) D^(3/2), a = sqrt(R D / 2) (validation.md section 3).
    """
    radius, modulus, poisson = 0.03, 1e6, 0.3
    config = load_config(overrides=[
        'dimension=3', 'fruit.model=solid', 'fruit.skin.enabled=false',
        f'fruit.mesh.subdivisions={subdivisions}', f'fruit.mesh.jaw_refinement={refinement}',
        f'fruit.mesh.order={order}',
        'world.gravity=0', 'world.table=false', 'fruit.density=50', 'fruit.damping.mass=20',
        f'sim.dt={dt}', 'sim.max_contact_passes=30', f'fruit.shape.diameter={2 * radius}',
        f'gripper.initial_gap={2 * radius}', f'fruit.flesh.youngs_modulus={modulus}',
        f'fruit.flesh.poisson_ratio={poisson}'])
    sim = make_simulation(config)
    width = sim.fruit.rest_width
    assert abs(width / (2 * radius) - 1) < 1e-9
    errors, penetration = {}, 0.0
    for ratio in (0.02, 0.05):
        travel = ratio * radius
        sim.command_gap(width - travel, 0.005 * radius / 0.05)
        while sim.gripper_state.gap > width - travel + 1e-12:
            sim.step()
        result = sim.run(0.1)
        hertz = (np.sqrt(2) / 3 * modulus / (1 - poisson ** 2) * np.sqrt(radius)
                 * travel ** 1.5)
        a = np.mean(result.deformation.jaw_contact_radii)
        errors[ratio] = (result.grip_force / hertz - 1, a / np.sqrt(radius * travel / 2) - 1)
        skin = result.positions[sim.fruit.surface, 0]
        depth = max(result.left_jaw_x - skin.min(), skin.max() - result.right_jaw_x)
        penetration = max(penetration, depth / travel)
    return errors, penetration


def pressed_wrinkling_shell(wrinkling, ratios, subdivisions=12, dt=0.05, radius=0.03):
    """A pressurised shell (turgor p, no bulk stiffness of the contents: constant
    pressure) with a thin, stiff skin (E_s t / (p R) = 1000, bending length
    sqrt(D / (p R / 2)) ~ 0.14 mm, small against the contact patch) pressed between two
    plates by delta per plate. Returns (deltas in m, plate forces F in N, p R)."""
    turgor = 2e4
    config = load_config(overrides=[
        'dimension=3', 'fruit.model=shell', 'world.gravity=0', 'world.table=false',
        'fruit.density=50', 'fruit.damping.mass=20', f'sim.dt={dt}',
        'sim.max_contact_passes=30', f'fruit.shape.diameter={2 * radius}',
        f'fruit.pressure.turgor={turgor}', 'fruit.pressure.bulk_modulus=0',
        'fruit.skin.youngs_modulus=6e10', 'fruit.skin.thickness=1e-5',
        f'fruit.mesh.subdivisions={subdivisions}', 'fruit.mesh.jaw_refinement=0.5',
        f'fruit.skin.wrinkling={str(wrinkling).lower()}'])
    sim = make_simulation(config)
    deltas, forces = [], []
    for delta, result, force in pressed_constant_pressure_shell(sim, radius, ratios, turgor):
        deltas.append(delta)
        forces.append(force)
    return np.array(deltas), np.array(forces), turgor * 0.5 * sim.fruit.rest_width


def pressed_constant_pressure_shell(sim, radius, ratios, turgor):
    """Close the plates of ``sim`` (a shell of radius m at constant pressure turgor Pa)
    by delta = ratio * radius each for every ratio in turn, settle 0.2 s; yields (delta
    m, the settled result, the left plate's force N), checking that the pressure stayed
    the turgor and that the plate force is the grip force."""
    width = sim.fruit.rest_width
    for ratio in ratios:
        delta = ratio * radius
        sim.command_gap(width - 2 * delta, 0.004)
        while sim.gripper_state.gap > width - 2 * delta + 1e-12:
            sim.step()
        result = sim.run(0.2)
        assert abs(sim.fruit.pressure.pressure(sim.q.ravel()) / turgor - 1) < 1e-6
        force = np.sum(result.contact_forces[result.contact_obstacle == 0, 0])  # left plate
        assert abs(force / result.grip_force - 1) < 1e-6
        yield delta, result, force


def kernel_evaluation(energy, q, hessian=True):
    """(value, gradient, dense Hessian incl. low-rank terms) from an energy's compiled
    ``evaluate_into``, with a dense (n, n) matrix standing in for the CSC values
    (scatter = row * n + column)."""
    n = q.size
    grad = np.zeros(n)
    data = np.zeros(n * n)
    if energy.dofs is None:
        scatter = np.zeros((0, 0), np.int64)
    else:
        m = energy.dofs.shape[1]
        scatter = (np.repeat(energy.dofs, m, axis=1) * n + np.tile(energy.dofs, (1, m)))
    value, low_rank = energy.evaluate_into(q, grad, data, scatter, hessian)
    dense = data.reshape(n, n)
    for c, u in low_rank:
        dense = dense + c * np.outer(u, u)
    return value, grad, dense
