"""The compiled contact passes (core.contact_kernels): one implementation for 2D and 3D.

A 2D set-up embedded in 3D (the y axis added as a second tangent of every face) gives
the same targets, filters and contact-set changes; a corner's filter is a symmetric
projector that keeps the node on both faces; the Coulomb cone is round in 3D; the
deepest-first rule; restitution that never adds energy; a node in an oblique corner
stays in the 2D whole-step kernel.
"""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core import contact as cm
from gripper_sim.core import contact_kernels as ck
from gripper_sim.core.obstacles import FlatFace
from gripper_sim.core.simulation import Simulation
from gripper_sim.core.obstacles import Plate

from reference_solver import reference_route

_Y = np.array([0.0, 1.0, 0.0])


def _embedded(face: FlatFace, origin_3d=None) -> Plate:
    """The 3D plate that is ``face`` (2D, in the x-z plane) extruded along y."""
    def lift(v):
        return np.array([v[0], 0.0, v[1]])
    return Plate(face.name, lift(face.origin) if origin_3d is None else origin_3d,
                 lift(face.normal), np.stack([lift(face.tangent), _Y]),
                 np.array([face.half_length, np.inf]), face.thickness, lift(face.velocity),
                 face.static_friction, face.kinetic_friction, face.restitution)


def _v_groove(shift=0.0, velocity=(0.0, 0.0)):
    """A table and the two flanks of a V (45 degrees), the V's bottom at x = 0, z = 0,
    the flanks moved by ``shift`` (m) along x and moving at ``velocity`` (m/s)."""
    s = np.sqrt(0.5)
    common = dict(thickness=0.01, static_friction=0.5, kinetic_friction=0.4,
                  restitution=0.5, velocity=np.array(velocity, float))
    return [FlatFace('left', np.array([shift, 0.0]), np.array([s, s]), half_length=0.02,
                     **common),
            FlatFace('right', np.array([shift, 0.0]), np.array([-s, s]), half_length=0.02,
                     **common),
            FlatFace('table', np.array([0.0, -0.004]), np.array([0.0, 1.0]), restitution=0.3,
                     static_friction=0.0, kinetic_friction=0.0)]


def _lift(points2d: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.column_stack([points2d[:, 0], y, points2d[:, 1]])


def _in_plane(array3d: np.ndarray) -> np.ndarray:
    return array3d[..., [0, 2]]


def _scene(seed=0, n=40):
    """Nodes near the V's bottom and the table, a contact state with every mode (held
    by each face, a corner), start and end positions and reactions; in 2D."""
    rng = np.random.default_rng(seed)
    x_n = rng.uniform([-0.006, -0.005], [0.006, 0.004], size=(n, 2))
    v_n = rng.normal(scale=0.05, size=(n, 2))
    x = x_n + rng.normal(scale=5e-4, size=(n, 2))
    reaction = rng.normal(scale=0.2, size=(n, 2))
    contacts = cm.ContactState.empty(n)
    contacts.obstacle[:12] = np.arange(12) % 3
    contacts.mode[:12] = [cm.STICK, cm.SLIP, cm.IMPACT, cm.SLIP] * 3
    contacts.normal_force[:12] = rng.uniform(0.0, 0.5, 12)
    contacts.bounce_speed[:12] = np.where(contacts.mode[:12] == cm.IMPACT, 0.02, 0.0)
    contacts.secondary[[1, 5]] = 1, 0
    return x_n, v_n, x, reaction, contacts


def test_a_2d_scene_embedded_in_3d_gives_the_same_passes():
    """Targets, filters, friction rows, the updated contact set, end velocities and
    forces of a V-groove scene in 2D equal those of the same scene extruded in 3D."""
    x_n, v_n, x, reaction, contacts = _scene()
    n, dt = len(x_n), 1e-3
    old, new = _v_groove(), _v_groove(shift=1e-4, velocity=(0.1, 0.0))
    y = np.random.default_rng(1).uniform(-0.01, 0.01, n)
    results = []
    for dim in (2, 3):
        if dim == 2:
            faces = ck.face_arrays(old, new, 2)
            xs = [x_n, x_n + dt * v_n, v_n, x, reaction]
        else:
            faces = ck.face_arrays([_embedded(f) for f in old], [_embedded(f) for f in new], 3)
            xs = [_lift(x_n, y), _lift(x_n + dt * v_n, y), _lift(v_n, 0 * y), _lift(x, y),
                  _lift(reaction, 0 * y)]
        start_x, pred, vel, end_x, react = (np.ascontiguousarray(a) for a in xs)
        state = contacts.copy()
        arrays = state.arrays()
        start, filters = np.empty((n, dim)), np.empty((n, dim, dim))
        fr_nodes, fr_bound = np.empty(n, np.int64), np.empty(n)
        fr_t, fr_speed = np.empty((n, dim - 1, dim)), np.empty((n, dim - 1))
        k = ck.constraints(arrays, faces, start_x, pred, dt, 0.05, start, filters, fr_nodes,
                           fr_t, fr_bound, fr_speed)
        released, slipped = np.zeros(n, bool), np.zeros(n, bool)
        changed = ck.update(arrays, faces, end_x, start_x, vel, react, np.arange(n), dt, 0.01,
                            5e-3, 0.0, released, slipped)
        after = state.copy()
        v_out, forces = np.empty((n, dim)), np.empty((n, dim))
        ck.finish(arrays, faces, end_x, start_x, vel, react, np.full(n, 0.002), dt, v_out,
                  forces)
        results.append(dict(start=start, filters=filters, k=k, fr_nodes=fr_nodes[:k],
                            fr_t=fr_t[:k, 0], fr_bound=fr_bound[:k], fr_speed=fr_speed[:k, 0],
                            changed=changed, after=after, final=state, v=v_out,
                            forces=forces, released=released, slipped=slipped))
    two, three = results
    assert two['k'] == three['k'] > 0
    np.testing.assert_allclose(_in_plane(three['start']), two['start'], rtol=0, atol=1e-15)
    np.testing.assert_allclose(three['start'][:, 1], y, rtol=0, atol=1e-15)
    three_in_plane = three['filters'][:, [0, 2]][:, :, [0, 2]]
    np.testing.assert_allclose(three_in_plane, two['filters'], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(three['fr_nodes'], two['fr_nodes'])
    np.testing.assert_allclose(_in_plane(three['fr_t']), two['fr_t'], atol=1e-15)
    np.testing.assert_allclose(three['fr_bound'], two['fr_bound'], atol=1e-15)
    np.testing.assert_allclose(three['fr_speed'], two['fr_speed'], atol=1e-15)
    assert two['changed'] and three['changed']
    for key in ('after', 'final'):
        for name in ('obstacle', 'mode', 'secondary'):
            np.testing.assert_array_equal(getattr(three[key], name), getattr(two[key], name))
        for name in ('normal_force', 'bounce_speed', 'secondary_bounce'):
            np.testing.assert_allclose(getattr(three[key], name), getattr(two[key], name),
                                       rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(three['released'], two['released'])
    np.testing.assert_array_equal(three['slipped'], two['slipped'])
    np.testing.assert_allclose(_in_plane(three['v']), two['v'], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(_in_plane(three['forces']), two['forces'], atol=1e-15)
    # every kind of change happened in the scene
    assert np.any(two['released']) and np.any(two['slipped'])
    caught = (contacts.obstacle < 0) & (two['after'].obstacle >= 0)
    assert np.any(caught)
    assert np.any(two['after'].mode == cm.IMPACT) and np.all(two['final'].mode != cm.IMPACT)


def test_a_corner_holds_the_node_on_both_faces_with_a_symmetric_projector():
    """A node sliding on one flank of a V and held by the other as a corner: its start
    is on both planes (the first at its target gap), its filter a symmetric projector
    that frees no direction out of either face (in 2D: none at all; in 3D: the V's edge)."""
    for dim, faces_of in ((2, lambda fs: fs), (3, lambda fs: [_embedded(f) for f in fs])):
        faces_2d = _v_groove()
        faces = ck.face_arrays(faces_of(faces_2d), faces_of(faces_2d), dim)
        contacts = cm.ContactState.empty(1)
        contacts.obstacle[0], contacts.mode[0], contacts.secondary[0] = 0, cm.SLIP, 1
        x_n = np.zeros((1, dim))
        x_n[0, 0], x_n[0, -1] = 3e-4, 1e-3
        start, filters = np.empty((1, dim)), np.empty((1, dim, dim))
        ck.constraints(contacts.arrays(), faces, x_n, x_n.copy(), 1e-3, 0.05, start,
                       filters, np.empty(1, np.int64), np.empty((1, dim - 1, dim)),
                       np.empty(1), np.empty((1, dim - 1)))
        s = filters[0]
        normals = faces[0][:2]
        np.testing.assert_allclose(start[0] @ normals.T, 0.0, atol=1e-15)
        np.testing.assert_array_equal(s, s.T)
        np.testing.assert_allclose(s @ s, s, atol=1e-15)
        np.testing.assert_allclose(s @ normals.T, 0.0, atol=1e-15)
        assert np.trace(s) == pytest.approx(dim - 2)


def test_the_coulomb_cone_is_round_in_3d():
    """A stuck node's tangential reaction (0.6, 0.6) N against 1 N normal leaves the cone
    mu_s = 0.8 (|R_t| = 0.85 N), though each component alone is inside; (0.5, 0.5) does
    not."""
    plate = Plate('table', np.zeros(3), np.array([0.0, 0.0, 1.0]),
                  np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), static_friction=0.8,
                  kinetic_friction=0.6)
    faces = ck.face_arrays([plate], [plate], 3)
    modes = []
    for r_t in (0.6, 0.5):
        contacts = cm.ContactState.empty(1)
        contacts.obstacle[0], contacts.mode[0] = 0, cm.STICK
        x = np.zeros((1, 3))
        ck.update(contacts.arrays(), faces, x, x.copy(), x.copy(), np.array([[r_t, r_t, 1.0]]),
                  np.zeros(0, np.int64), 1e-3, 0.01, 5e-3, 0.0, np.zeros(1, bool),
                  np.zeros(1, bool))
        modes.append(int(contacts.mode[0]))
        assert contacts.normal_force[0] == 1.0
    assert modes == [cm.SLIP, cm.STICK]


def test_deepest_first_catches_the_deep_nodes_of_each_face_first():
    """Free nodes 1.0, 0.8 and 0.5 mm inside the table: with deepest_first 0.7 the first
    two are caught, with 0 all three; a node covered by no face is never caught."""
    table = Plate('table', np.zeros(3), np.array([0.0, 0.0, 1.0]),
                  np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                  half_extents=np.array([0.01, 0.01]), static_friction=0.5)
    faces = ck.face_arrays([table], [table], 3)
    x = np.array([[0.0, 0.0, -1e-3], [0.001, 0.0, -8e-4], [0.002, 0.0, -5e-4],
                  [0.05, 0.0, -2e-3]])
    for fraction, caught in ((0.7, [0, 0, -1, -1]), (0.0, [0, 0, 0, -1])):
        contacts = cm.ContactState.empty(4)
        assert ck.update(contacts.arrays(), faces, x, x.copy(), np.zeros((4, 3)),
                         np.zeros((4, 3)), np.arange(4), 1e-3, 0.01, 5e-3, fraction,
                         np.zeros(4, bool), np.zeros(4, bool))
        assert contacts.obstacle.tolist() == caught
        assert np.all(contacts.mode[contacts.obstacle >= 0] == cm.STICK)


@pytest.mark.parametrize('dim', [2, 3])
def test_a_capped_rebound_never_adds_energy(dim):
    """Random nodes and rebounds: the full rebound is kept when it fits in the budget
    |v_start|^2 + 2 F . dx / m; else the largest scale that fits is taken (the end speed
    squared meets the budget, no larger scale fits), or none (0) when no scale fits."""
    rng = np.random.default_rng(dim)
    grid = np.linspace(0.0, 1.0, 201)
    kept = capped = dropped = 0
    for _ in range(400):
        v_start, dx, reaction, rebound = rng.normal(size=(4, dim))
        rebound *= rng.uniform(0.0, 3.0)
        v = rng.normal(size=dim) + rebound
        mass, dt = rng.uniform(0.5, 2.0), rng.uniform(0.01, 1.0)
        scale = ck.capped_rebound_scale(v, rebound, v_start, dx, reaction, mass, dt)
        others = mass * (dx / dt - v_start) / dt - reaction
        budget = v_start @ v_start + 2.0 * others @ dx / mass
        speeds = np.sum((v - rebound + grid[:, None] * rebound) ** 2, axis=1)  # (201,)
        out = v - (1.0 - scale) * rebound
        if v @ v <= budget:
            assert scale == 1.0
            kept += 1
        elif scale > 0.0:
            assert out @ out == pytest.approx(budget, rel=1e-9, abs=1e-12)
            assert np.all(speeds[grid > scale + 1e-9] > budget)
            capped += 1
        else:
            assert scale == 0.0 and np.all(speeds[1:] > budget)
            dropped += 1
    assert kept > 20 and capped > 20 and dropped > 5
    # only more than the full rebound would fit ((s - 2)^2 <= 0.25: s in [1.5, 2.5]):
    # none is kept
    normal = np.eye(dim)[0]
    assert ck.capped_rebound_scale(-normal, normal, 0.5 * normal, np.zeros(dim),
                                   np.zeros(dim), 1.0, 0.01) == 0.0


def test_a_node_in_an_oblique_corner_stays_in_the_whole_step_kernel():
    """A point sliding on a frictionless table into the lower flank of a V-groove jaw
    (85 degrees to the table) is held by both: the 2D kernel steps it (no step left to
    the shared route) on the same trajectory as the shared route."""
    config = load_config(overrides=[
        'fruit.model=point', 'gripper.finger.type=vgroove', 'gripper.finger.groove_angle=170',
        'gripper.initial_lift=0.002', 'gripper.initial_gap=0.012',
        'fruit.initial_velocity.x=0.1', 'contact.table.static_friction=0',
        'contact.table.kinetic_friction=0'])
    kernel = Simulation(config, fast=True)
    shared = reference_route(Simulation(config, fast=False))
    in_corner = 0
    for _ in range(300):
        a, b = kernel.step(), shared.step()
        np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(kernel.contacts.secondary, shared.contacts.secondary)
        in_corner += int(kernel.contacts.secondary[0] >= 0)
    assert in_corner > 200
    assert kernel._fast.fallbacks == 0
    assert kernel.contacts.obstacle[0] == 4  # held by the table, the right jaw's flank
    assert kernel.contacts.secondary[0] == 2  # its second face
    assert a.positions[0, 1] == pytest.approx(0.0, abs=1e-9)  # on the table


class _PullingSolver:
    """A solve that returns its start with a reaction pulling every node off the
    table (-1 N along z), counting its calls."""

    def __init__(self, n):
        self.m = np.ones(2 * n)
        self.calls = 0

    def solve(self, q_n, v_n, dt, q_start, constraints):
        from gripper_sim.core.stepper import StepSolution
        self.calls += 1
        reaction = np.zeros_like(q_start)
        reaction[1::2] = -1.0
        return StepSolution(q_start.copy(), reaction, 1, [1.0])


def test_a_node_released_in_a_pass_and_found_inside_again_is_held_to_the_steps_end():
    # a stuck node 1 mm inside the table whose reaction pulls: the first pass releases
    # it and, finding it still 0.9 mm inside, holds it again; the second keeps it held
    # though its reaction still pulls (a node is released once a step: the passes cannot
    # cycle), and the passes end with it held, not inside. Before, the passes left it
    # free and inside (the 3D friction hold ended with a node 10 um inside a closing jaw)
    from gripper_sim.core.contact_passes import ContactSettings, contact_step
    table = FlatFace('table', np.zeros(2), np.array([0.0, 1.0]), static_friction=0.5,
                     kinetic_friction=0.4)
    contacts = cm.ContactState.empty(1)
    contacts.obstacle[0] = 0
    contacts.mode[0] = cm.STICK
    solver = _PullingSolver(1)
    settings = ContactSettings(max_passes=10, max_correction_speed=0.1,
                               release_threshold=1e-6, gravity=9.81)
    outcome = contact_step(solver, np.array([0]), contacts, np.array([[0.0, -1e-3]]),
                           np.zeros((1, 2)), [table], [table], 1e-3, settings)
    assert solver.calls == 2 and outcome.iterations == 2
    assert outcome.contacts.obstacle[0] == 0 and outcome.contacts.mode[0] == cm.STICK


def test_one_loop_drives_the_contact_passes():
    # the per-pass kernels are called by the one pass driver only (run by Python in
    # contact_step, compiled in the 2D whole-step kernel): no second pass loop
    from pathlib import Path
    import gripper_sim
    root = Path(gripper_sim.__file__).parent
    callers = sorted(str(path.relative_to(root)) for path in root.rglob('*.py')
                     for call in ('ck.update(', 'contact_kernels.update(', 'ck.finish(',
                                  'contact_kernels.finish(')
                     if call in path.read_text())
    assert callers == ['core/contact_passes.py', 'core/contact_passes.py']
