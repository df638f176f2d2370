"""Deformable fingers (``core.soft_fingers``): soft-on-soft barrier contact in the 2D core.

The two-way barrier against finite differences; two equal elastic disks pressed together give Hertz's half-width with the combined
modulus and radius; a disk pressed by pads as stiff as itself is symmetric; no vertex of
either body ever gets inside the other (checked at every step); the default apple is
picked with the solid pad in force mode; bad configurations are one-line errors.

The contact half-width is read from the contact forces: Hertz's pressure is elliptical,
p(s) = p0 sqrt(1 - s^2 / a^2), whose second moment about its centre is a^2 / 4, so
a = 2 sqrt(sum f_i s_i^2 / sum f_i) over the nodes' normal contact forces f_i at s_i.
"""
import ipctk
import numpy as np
import pytest

from helpers import QUASI_STATIC, kernel_evaluation

from gripper_sim.configuration import load_config
from gripper_sim.core.barrier import BarrierContact, BarrierSettings, SoftBody
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.mesh import boundary_edges, mesh_outline, points_inside
from gripper_sim.core.newton import INFEASIBLE_START
from gripper_sim.core.simulation import Simulation
from gripper_sim.core.stepper import NEWTON_FAILURES, NewtonFailure
from gripper_sim.errors import CommandError, ConfigError, ConfigWarning
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import GraspSequence, evaluate, run_grasp

RADIUS = 0.03
MODULUS = 1e6
POISSON = 0.3
DEPTH = 0.01  # QUASI_STATIC's fruit.depth


def disk_finger(radius, nodes, modulus, poisson, depth, density=50.0) -> FingerBody:
    """A solid disk touching the backing line x = 0 at its back, its back third (the
    nodes within 60 degrees of the backing) bonded to the jaw; its front half may touch."""
    angles = np.linspace(0.0, 2 * np.pi, nodes, endpoint=False)
    outline = np.stack([radius * (1 + np.cos(angles)), radius * np.sin(angles)], axis=1)
    positions, triangles = mesh_outline(outline)
    p = positions[triangles]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    masses = np.zeros(len(positions))
    np.add.at(masses, triangles.ravel(), np.repeat(density * area * depth / 3.0, 3))
    back = np.flatnonzero(np.cos(angles) < -np.cos(np.radians(60.0)))
    front = np.flatnonzero(np.cos(angles) > 0.0)
    edges = np.array([(i, (i + 1) % nodes) for i in front if (i + 1) % nodes in front])
    return FingerBody('disk', positions, masses, back, edges, 0, depth,
                      triangles=triangles, youngs_modulus=modulus, poisson_ratio=poisson)


def closed_outline(triangles: np.ndarray) -> np.ndarray:
    """(k,) the boundary nodes of a triangle mesh, in order around it."""
    edges = boundary_edges(triangles)
    following = {}
    for a, b in edges:
        following.setdefault(a, []).append(b)
        following.setdefault(b, []).append(a)
    start = next(iter(following))
    loop, previous = [start], None
    while True:
        here = loop[-1]
        step = [n for n in following[here] if n != previous][0]
        if step == start:
            return np.array(loop)
        previous = here
        loop.append(step)


DHAT = 1e-4


def _two_way_barrier():
    """A barrier between a three-node fruit chain (nodes 0-2) and a soft body's segment
    (nodes 3, 4) hovering within dhat above it, the segment sliding along the chain since
    the start of the step (so the lagged friction acts too); (barrier, positions (5, 2))."""
    x = np.array([[0.0, 0.0], [1.0, 0.1], [2.0, 0.0], [0.6, 0.6], [1.6, 0.5]]) * DHAT
    body = SoftBody(np.array([3, 4]), np.array([[3, 4]]), 0.5, 0.4)
    barrier = BarrierContact(5, np.arange(3), np.array([[0, 1], [1, 2]]),
                             BarrierSettings(dhat=DHAT, stiffness=0.5,
                                             friction_smoothing=1e-3), bodies=(body,))
    start = x.copy()
    start[3:] -= np.array([0.05 * DHAT, 0.0])
    barrier.begin_step(start, [], [], 1e-3)
    return barrier, x


def test_two_way_barrier_matches_finite_differences_on_both_bodies():
    barrier, x = _two_way_barrier()
    barrier.projection = ipctk.PSDProjectionMethod.NONE  # the exact Hessian (not its PSD part)
    q = x.ravel() + 0.03 * DHAT * np.sin(np.arange(10.0))
    ev = barrier.evaluate(q)
    dense = barrier.hessian(q)
    # both bodies feel the contact, equal and opposite
    assert np.abs(ev.gradient[:6]).max() > 0 and np.abs(ev.gradient[6:]).max() > 0
    assert ev.gradient.reshape(-1, 2).sum(axis=0) == pytest.approx(
        np.zeros(2), abs=1e-9 * np.abs(ev.gradient).max())
    h = 1e-4 * DHAT
    eye = np.eye(q.size)
    fd_grad = np.array([(barrier.value(q + h * e) - barrier.value(q - h * e)) / (2 * h)
                        for e in eye])
    fd_hess = np.array([(barrier.gradient(q + h * e) - barrier.gradient(q - h * e)) / (2 * h)
                        for e in eye])
    assert ev.gradient == pytest.approx(fd_grad, rel=1e-5, abs=1e-6 * np.abs(fd_grad).max())
    assert np.abs(dense).max() > 0
    assert dense == pytest.approx(fd_hess, rel=1e-4, abs=1e-5 * np.abs(fd_hess).max())
    value, gradient, kernel_dense = kernel_evaluation(barrier, q)
    assert value == pytest.approx(ev.value) and gradient == pytest.approx(ev.gradient)
    assert kernel_dense == pytest.approx(dense)
    # the solver's Hessian: each pair's PSD part, so the sum is PSD
    barrier.projection = ipctk.PSDProjectionMethod.CLAMP
    assert np.linalg.eigvalsh(barrier.hessian(q)).min() > -1e-9 * np.abs(dense).max()


def test_a_pattern_grows_by_the_pairs_near_contact_once_couplings_were_left_out():
    """A barrier whose pattern holds one fruit-body pair: while no entry fell outside it,
    it does not grow; once one did (``left_out``), the pairs within twice the longest
    edge join it (their dofs too), once; ``restore_pattern`` goes back to the pairs
    given."""
    x = np.array([[0.0, 0.0], [1.0, 0.1], [2.0, 0.0], [0.6, 0.6], [1.6, 0.5],
                  [3.0, 0.6]]) * DHAT
    body = SoftBody(np.array([3, 4, 5]), np.array([[3, 4], [4, 5]]), 0.5, 0.4)
    given = np.array([[0, 3]])
    barrier = BarrierContact(6, np.arange(3), np.array([[0, 1], [1, 2]]),
                             BarrierSettings(dhat=DHAT, stiffness=0.5,
                                             friction_smoothing=1e-3),
                             bodies=(body,), pairs=given)
    assert not barrier.grow_pattern(x)
    keys = barrier._pattern_keys.size
    barrier.left_out = True
    assert barrier.grow_pattern(x)
    reach = 2.0 * np.linalg.norm(x[5] - x[4])  # the longest edge: the body's second
    near = {(i, j) for i in range(3) for j in range(3, 6)
            if np.linalg.norm(x[i] - x[j]) <= reach}
    assert {tuple(p) for p in barrier.pattern_pairs} == near | {(0, 3)}
    assert (0, 5) not in near and (2, 5) in near
    assert barrier._pattern_keys.size > keys
    assert {tuple(row) for row in barrier.dofs[:, [0, 2]] // 2} >= near
    assert not barrier.left_out and not barrier.grow_pattern(x)
    assert barrier.restore_pattern()
    assert np.array_equal(barrier.pattern_pairs, given) and barrier._pattern_keys.size == keys
    assert not barrier.restore_pattern()


def test_a_self_contact_pattern_grows_by_each_bodys_own_pairs_near_contact():
    """A self-contact barrier over two copies of a bent chain whose pattern holds one
    pair: once couplings were left out, the node pairs of one copy within twice the
    longest edge join it (lower node first), never a pair across copies; restored,
    back to the pair given."""
    chain = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 0.8], [1.0, 0.8],
                      [0.0, 0.8]]) * DHAT
    edges = np.column_stack([np.arange(5), np.arange(1, 6)])
    x = np.vstack([chain, chain + [0.5 * DHAT, 0.3 * DHAT]])  # the copies overlap
    copies = (np.arange(6), np.arange(6, 12))
    bodies = tuple(SoftBody(copy, copy[edges], 0.0, 0.0) for copy in copies)
    given = np.array([[0, 5]])
    barrier = BarrierContact(12, np.zeros(0, np.int64), np.zeros((0, 2), np.int64),
                             BarrierSettings(dhat=DHAT, stiffness=0.5), bodies=bodies,
                             pairs=given, self_contact=True)
    keys = barrier._pattern_keys.size
    barrier.left_out = True
    assert barrier.grow_pattern(x)
    reach = 2.0 * DHAT  # twice the longest edge (1 dhat)
    near = {(copy[i], copy[j]) for copy in copies for i in range(6) for j in range(i + 1, 6)
            if np.linalg.norm(chain[i] - chain[j]) <= reach}
    assert {tuple(p) for p in barrier.pattern_pairs} == near | {(0, 5)}
    assert (0, 3) not in near and (1, 4) in near and (7, 10) in near
    assert barrier._pattern_keys.size > keys
    assert barrier.restore_pattern()
    assert np.array_equal(barrier.pattern_pairs, given) and barrier._pattern_keys.size == keys


def test_two_way_collision_free_step_stops_a_finger_node_before_the_fruit():
    barrier, x = _two_way_barrier()
    q = x.ravel()
    through = np.zeros_like(q)
    through[7] = -10 * DHAT  # node 3 of the soft body straight down through the chain
    fraction = barrier.max_step(q, through)
    assert 0 < fraction < 0.1
    assert barrier.max_step(q, -through) == 1.0


def _pairs(collisions) -> list:
    """The (kind, ids) of the pairs of an ipctk NormalCollisions (a vertex pair in either
    order), sorted."""
    return sorted([('ev', c.vertex_id, c.edge_id) for c in collisions.ev_collisions]
                  + [('vv', *sorted((c.vertex0_id, c.vertex1_id)))
                     for c in collisions.vv_collisions])


def test_the_barrier_broad_phase_finds_the_pairs_of_the_default_one():
    barrier, x = _two_way_barrier()
    found = 0
    for k in range(20):
        q = x.ravel() + 0.3 * DHAT * np.sin(np.arange(10.0) * (k + 1))
        v = barrier.vertices(q.reshape(-1, 2))
        default = ipctk.NormalCollisions()
        default.build(barrier._mesh, v, DHAT)
        assert _pairs(barrier._collisions(v)) == _pairs(default)
        found += len(default)
    assert found > 0


def test_the_outputs_read_again_at_a_solution_equal_a_fresh_evaluation():
    """The barrier keeps its last evaluation for the outputs read at the same positions;
    other positions in between, and a new step, give what a fresh barrier gives."""
    barrier, x = _two_way_barrier()
    fresh, _ = _two_way_barrier()
    q1 = x.ravel() + 0.03 * DHAT * np.sin(np.arange(10.0))
    q2 = x.ravel() + 0.05 * DHAT * np.cos(np.arange(10.0))
    barrier.evaluate(q1)
    assert np.abs(barrier.contact_forces(q1)).max() > 0
    assert barrier.contact_forces(q1) == pytest.approx(fresh.contact_forces(q1), rel=1e-12)
    barrier.evaluate(q2, hessian=False)
    for q in (q1, q2):
        assert barrier.normal_forces(q) == pytest.approx(fresh.normal_forces(q), rel=1e-12)
        assert barrier.contact_forces(q) == pytest.approx(fresh.contact_forces(q), rel=1e-12)
        assert np.array_equal(barrier.partners(q), fresh.partners(q))
    # a new step (another start: another lagged friction) forgets the kept evaluation
    before = barrier.contact_forces(q1)
    later = x + np.array([0.02 * DHAT, 0.0])
    barrier.begin_step(later, [], [], 1e-3)
    fresh.begin_step(later, [], [], 1e-3)
    after = barrier.contact_forces(q1)
    assert not np.allclose(after, before, rtol=1e-6, atol=0.0)
    assert after == pytest.approx(fresh.contact_forces(q1), rel=1e-12)


class PenetrationCheck:
    """Called after every step: the smallest signed clearance so far, negative once a
    vertex of the fruit is inside a finger or a finger's vertex inside the fruit."""

    def __init__(self, sim: Simulation):
        self.sim = sim
        body = sim._soft.body
        self.finger_outline = closed_outline(body.triangles)
        self.inside = 0

    def __call__(self, result) -> None:
        fruit_outline = result.positions[result.surface]
        m = self.sim._soft.body.n_nodes
        for side in range(2):
            finger = result.fingers.positions[side * m:(side + 1) * m]
            polygon = finger[self.finger_outline]
            self.inside += int(np.sum(points_inside(polygon, fruit_outline)))
            self.inside += int(np.sum(points_inside(fruit_outline, finger)))


def moment_half_width(positions: np.ndarray, forces: np.ndarray) -> float:
    """m, a = 2 sqrt(sum f s^2 / sum f) of normal forces (k,) N at positions (k,) m."""
    total = forces.sum()
    centre = forces @ positions / total
    return 2.0 * float(np.sqrt(forces @ (positions - centre) ** 2 / total))


def normal_forces(sim: Simulation, result) -> np.ndarray:
    """(n + 2 m, 2) N, the barrier's (normal) contact forces on the fruit's nodes, then
    the fingers'."""
    return sim._barrier.normal_forces(
        np.vstack([result.positions, result.fingers.positions]).ravel())


def fruit_side_half_width(sim: Simulation, result, side: str) -> float:
    """The contact half-width on the fruit from its nodes touching the ``side`` finger."""
    index = result.obstacle_names.index(side)
    nodes = np.flatnonzero(result.contact_obstacle == index)
    forces = np.linalg.norm(normal_forces(sim, result)[nodes], axis=1)
    return moment_half_width(result.positions[nodes, 1], forces)


def squeeze(finger, force, fruit_nodes, *overrides, gap_margin=2e-3):
    """A solid disk (RADIUS, MODULUS, POISSON) squeezed quasi-statically in force mode
    between two deformable fingers; (sim, last result, penetration check)."""
    config = load_config(overrides=QUASI_STATIC + [
        'fruit.model=solid', 'fruit.skin.enabled=false', f'fruit.nodes={fruit_nodes}',
        f'fruit.shape.diameter={2 * RADIUS}', f'fruit.flesh.youngs_modulus={MODULUS}',
        f'fruit.flesh.poisson_ratio={POISSON}', *overrides])
    reach = 0.0 if finger is None else float(finger.rest_positions[:, 0].max())
    if finger is not None:
        config = config.replaced({'gripper.initial_gap': 2 * RADIUS + 2 * reach + gap_margin})
    sim = Simulation(config, finger=finger)
    check = PenetrationCheck(sim)
    sim.add_observer(check)
    sim.command_force(force, speed=0.01)
    result = sim.run(1.0)
    return sim, result, check


@pytest.fixture(scope='module')
def two_disks():
    finger = disk_finger(RADIUS, 160, MODULUS, POISSON, DEPTH)
    return squeeze(finger, 4.0, 160)


def test_two_equal_disks_give_hertz_half_width(two_disks):
    sim, result, check = two_disks
    assert check.inside == 0
    assert result.grip_force == pytest.approx(4.0, rel=0.01)
    e_star = 1.0 / (2 * (1 - POISSON ** 2) / MODULUS)
    r_star = 1.0 / (2.0 / RADIUS)
    hertz = np.sqrt(4 * result.grip_force * r_star / (np.pi * e_star * DEPTH))
    for side in ('left_jaw', 'right_jaw'):
        assert fruit_side_half_width(sim, result, side) == pytest.approx(hertz, rel=0.10)


def test_the_fingers_feel_the_grip_at_their_bases(two_disks):
    """Quasi-static: each jaw's reaction equals the contact force the fruit puts on its
    finger, which equals the fingers' force on the fruit (two-way contact)."""
    sim, result, _ = two_disks
    m = sim._soft.body.n_nodes
    on_left = result.fingers.contact_forces[:m].sum(axis=0)
    on_right = result.fingers.contact_forces[m:].sum(axis=0)
    assert on_left[0] < 0 < on_right[0]
    assert -on_left[0] == pytest.approx(result.grip_force, rel=0.01)
    assert result.left_wrench.force[0] == pytest.approx(on_left[0], rel=0.01)
    assert result.right_wrench.force[0] == pytest.approx(on_right[0], rel=0.01)
    fruit_total = result.contact_forces.sum(axis=0)
    assert np.abs(fruit_total + on_left + on_right).max() < 1e-6 * result.grip_force


@pytest.fixture(scope='module')
def equal_pads():
    return squeeze(None, 3.0, 128, 'gripper.finger.type=solid_pad',
                   f'gripper.finger.solid_pad.youngs_modulus={MODULUS}',
                   f'gripper.finger.solid_pad.poisson_ratio={POISSON}',
                   'gripper.finger.solid_pad.density=50', 'gripper.initial_gap=0.0765')


def test_disk_pressed_by_equally_stiff_pads_is_symmetric(equal_pads):
    sim, result, check = equal_pads
    assert check.inside == 0
    assert result.grip_force == pytest.approx(3.0, rel=0.01)
    left, right = (fruit_side_half_width(sim, result, side) for side in ('left_jaw', 'right_jaw'))
    assert left > 0 and right == pytest.approx(left, rel=0.03)
    lengths = result.fingers.contact_length
    assert lengths[0] > 0 and lengths[1] == pytest.approx(lengths[0], rel=0.03)
    # both bodies of a contact carry one patch: the pad's half-width is the fruit's (a
    # fruit vertex's force spreads over the two ends of the pad edge it presses, which
    # widens the pad's moment by about the 1.5 mm node spacing: 7 % here)
    m, n = sim._soft.body.n_nodes, len(result.positions)
    forces = np.linalg.norm(normal_forces(sim, result)[n:n + m], axis=1)
    loaded = forces > 0
    pad_width = moment_half_width(result.fingers.positions[:m][loaded, 1], forces[loaded])
    assert pad_width == pytest.approx(left, rel=0.10)
    # the two pads deform as mirror images (the tip displacements are in each finger's
    # own frame)
    tip = result.fingers.tip_displacement
    assert np.abs(tip[0]).max() > 0 and tip[1] == pytest.approx(tip[0], rel=0.01)


def test_grasp_and_lift_of_the_apple_with_solid_pads():
    # the pads 1 mm from the apple (63.5 mm) at the start: a short closing
    sim = Simulation(load_config(overrides=['gripper.finger.type=solid_pad',
                                            'gripper.initial_gap=0.0775']))
    check = PenetrationCheck(sim)
    misses = []

    phases = []

    def on_step(result, phase):
        # phase: after this step; the step itself ran in the phase before it (the one
        # that ends the closing may stop short of the force at the speed limit)
        check(result)
        if phases and phases[-1] in ('squeezing', 'lifting', 'holding'):
            misses.append(abs(result.grip_force / 4.0 - 1.0))
        phases.append(phase)
    summary = run_grasp(sim, GraspSequence(sim, 4.0, lift_height=0.01, hold_time=0.2),
                        on_step=on_step)
    assert summary['outcome'] == 'held'
    assert check.inside == 0
    assert max(misses) <= 0.005 + 1e-9  # the jaw drive's FORCE_TOLERANCE
    result = sim.last
    assert result.in_contact_with('left_jaw') and result.in_contact_with('right_jaw')
    assert np.all(result.fingers.contact_length > 0)
    assert result.deformation.contact_length > 0 and result.damage is not None
    on_fingers = np.isin(result.contact_obstacle, [0, 1])
    assert not result.slipping and np.all(result.contact_sticking[on_fingers])


# ---------------------------------------------------------------------- bad configurations
@pytest.mark.parametrize('value', [0, -0.002])
def test_zero_or_negative_thickness_is_refused(value):
    with pytest.raises(ConfigError, match="'gripper.finger.solid_pad.thickness'.*must be >"):
        load_config(overrides=['gripper.finger.type=solid_pad',
                               f'gripper.finger.solid_pad.thickness={value}'])


@pytest.mark.parametrize('dimension', [2, 3])
def test_a_pad_too_thin_for_its_layers_is_refused_not_meshed(dimension):
    # inside the key's range (> 0): in 2D 1.6 million rows of cells took 24 GB before
    # the check and the process was killed; in 3D the step failed at t = 0
    with pytest.raises(ConfigError) as info:
        load_config(overrides=[f'dimension={dimension}', 'gripper.finger.type=solid_pad',
                               'gripper.finger.solid_pad.thickness=1e-7'])
    assert str(info.value) == (
        "config key 'gripper.finger.solid_pad.thickness' = 1e-07 m: too thin for its 4 "
        'layers: its cells across it (2.5e-08 m) are 1.6e+06 times smaller than the jaw '
        'height (0.04 m), at most 400 (the 2D pad meshes that many rows of square cells): '
        'use a thickness of 0.0004 m or more, or fewer layers '
        '(gripper.finger.solid_pad.layers)')


def test_the_thinnest_pad_the_error_suggests_is_meshed():
    pad = Simulation(load_config(overrides=['gripper.finger.type=solid_pad',
                                            'gripper.finger.solid_pad.thickness=0.0004']))
    assert pad._soft.body.n_nodes == 5 * 401  # 4 layers, 400 rows


def test_fingers_that_fill_the_stroke_are_refused():
    config = load_config(overrides=['gripper.finger.type=solid_pad', 'gripper.max_gap=0.05',
                                    'gripper.finger.solid_pad.thickness=0.03'])
    with pytest.raises(ConfigError, match='solid_pad.thickness.*fill the jaw stroke'):
        Simulation(config)


@pytest.mark.parametrize('override,key', [('gripper.initial_gap=0.07', 'gripper.initial_gap'),
                                          ('gripper.max_gap=0.07', 'gripper.max_gap')])
def test_a_fruit_that_does_not_fit_between_the_fingers_is_refused(override, key):
    config = load_config(overrides=['gripper.finger.type=solid_pad', override])
    with pytest.raises(ConfigError, match=f"'{key}'.*does not fit between the solid_pad"):
        Simulation(config)


def test_an_open_gap_at_which_the_fingers_overlap_is_refused():
    """Fingers far above the fruit touch it at no gap; an open gap below their stop (two
    6 mm pads: 12 mm) is refused, and the default opens them 1 cm past it."""
    above = ['gripper.finger.type=solid_pad', 'gripper.initial_lift=0.3']
    with pytest.raises(ConfigError, match="'gripper.initial_gap'.*overlap at the open gap"):
        Simulation(load_config(overrides=above + ['gripper.initial_gap=0.011']))
    assert Simulation(load_config(overrides=above)).initial_gap == pytest.approx(0.022)


@pytest.mark.parametrize('override,match', [('gripper.finger.pad.enabled=true', 'pad.enabled'),
                                            ('contact.restitution=0.5', 'restitution')])
def test_unsupported_combinations_are_refused(override, match):
    with pytest.raises(ConfigError, match=match):
        Simulation(load_config(overrides=['gripper.finger.type=solid_pad', override]))


def test_errors_are_one_line():
    for overrides in (['gripper.finger.type=solid_pad', 'gripper.finger.solid_pad.thickness=0'],
                      ['gripper.finger.type=fin_ray', 'gripper.finger.fin_ray.rib_angle=-50']):
        with pytest.raises(ConfigError) as info:
            load_config(overrides=overrides)
        assert '\n' not in str(info.value)
    with pytest.raises(ConfigError) as info:
        Simulation(load_config(overrides=['gripper.finger.type=solid_pad',
                                          'gripper.initial_gap=0.07']))
    assert '\n' not in str(info.value)


def test_a_gap_that_presses_the_fingers_together_is_a_command_error():
    sim = Simulation(load_config(overrides=['gripper.finger.type=solid_pad']))
    with pytest.raises(CommandError, match='press the two deformable fingers'):
        sim.command_gap(0.011)  # two 6 mm pads
    sim.command_gap(0.012)
    assert sim.gripper_state.target_gap == 0.012


@pytest.mark.parametrize('dimension', [2, 3])
def test_force_mode_jaws_stop_where_the_fingers_meet_and_the_grasp_says_so(dimension):
    """Closing in force mode on nothing (the fingers far above the fruit), the jaws stop
    at their stop, where the two pads' fronts meet, instead of pressing the fingers
    through each other (the model has no contact between them); the grasp ends 'failed'
    and its message names the stop. Before, the 3D Fin Ray's jaws closed 8 mm past it."""
    coarse = ['fruit.mesh.subdivisions=3'] if dimension == 3 else []
    config = load_config(overrides=['gripper.finger.type=solid_pad', f'dimension={dimension}',
                                    'gripper.initial_lift=0.3', *coarse])
    sim = make_simulation(config)
    assert sim.smallest_gap == pytest.approx(0.012)   # two 6 mm pads
    gaps = []
    sim.add_observer(lambda result: gaps.append(result.gap))
    evaluation = evaluate(sim, GraspSequence(sim, 5.0, close_speed=0.2), 5.0, time_limit=2.0)
    assert evaluation.outcome == 'failed'
    assert 'at their stop, a 12 mm gap' in evaluation.message
    assert evaluation.peak_grip_force == 0.0
    assert min(gaps) == pytest.approx(sim.smallest_gap, abs=1e-12)
    assert gaps[-1] == pytest.approx(sim.smallest_gap, abs=1e-12)


@pytest.mark.parametrize('overrides,key', [
    (['gripper.finger.type=solid_pad', 'contact.model=ipc'], 'contact.model'),
    (['gripper.finger.solid_pad.thickness=0.004'], 'gripper.finger.solid_pad.thickness')])
def test_keys_without_effect_are_warned_about(overrides, key):
    with pytest.warns(ConfigWarning, match=f"'{key}' has no effect"):
        load_config(overrides=overrides)


def test_the_solid_pad_preset_is_the_built_in_solid_pad():
    preset = load_config(finger='solid_pad')
    built_in = load_config(overrides=['gripper.finger.type=solid_pad'])
    keys = [k for k in built_in if k.startswith('gripper.finger.solid_pad.')]
    assert len(keys) == 5
    assert {k: preset[k] for k in keys} == {k: built_in[k] for k in keys}
    assert preset['gripper.finger.type'] == 'solid_pad'


def test_a_step_failed_on_an_inverted_element_names_the_fingers_too():
    failure = NewtonFailure(NEWTON_FAILURES[INFEASIBLE_START], [])
    pad = Simulation(load_config(overrides=['gripper.finger.type=solid_pad']))
    assert pad._convergence_advice(failure).startswith(
        'an element of the fruit or of a solid_pad finger inverted (it is crushed)')
    rigid = Simulation(load_config())
    assert rigid._convergence_advice(failure).startswith(
        'an element of the fruit inverted (it is crushed)')


def test_a_soft_steps_compiled_set_up_is_the_step_by_step_one(monkeypatch):
    """A soft-body step's set-up (``set_up_starts``: one compiled call) makes the
    starts that ``begin_step`` and ``pushed_starts`` make one by one with the fingers'
    bases at their targets, and ``start_clear`` answers as ``reachable``'s compiled
    check, bit for bit, in a Fin Ray grasp while the jaws close on the apple."""
    from gripper_sim.core import barrier_part as bp

    calls = []
    original = BarrierContact.set_up_starts

    def recorded(self, x_n, v_n, old, new, dt, fixed, targets, both):
        calls.append((self, x_n.copy(), v_n.copy(), old, new, dt, fixed, targets.copy()))
        return original(self, x_n, v_n, old, new, dt, fixed, targets, both)
    monkeypatch.setattr(BarrierContact, 'set_up_starts', recorded)
    config = load_config(overrides=['gripper.finger.type=fin_ray'])
    sim = Simulation(config.replaced(
        {'gripper.initial_gap': Simulation(config).touching_gap + 0.001}))
    sim.command_force(4.0, speed=0.01)
    for _ in range(150):
        result = sim.step()
    assert result.grip_force > 0.5  # the fingers press on the apple
    barrier, x_n, v_n, old, new, dt, fixed, targets = calls[-1]
    assert np.abs(targets - x_n[fixed]).max() > 0  # the bases move in the step
    plain, predicted, predicted_clear, plain_clear, difference = original(
        barrier, x_n, v_n, old, new, dt, fixed, targets, True)
    barrier.begin_step(x_n, old, new, dt)
    by_steps = barrier.pushed_starts(x_n, old, new, x_n + dt * v_n)
    for fused, start, clear in zip((plain, predicted), by_steps,
                                   (plain_clear, predicted_clear)):
        start[fixed] = targets
        assert np.array_equal(fused, start)
        assert clear == bp.start_clear(barrier._part, barrier._start_q, start.ravel(),
                                       barrier._faces_shift)
    assert predicted_clear and difference == np.abs(predicted - plain).max() > 0
