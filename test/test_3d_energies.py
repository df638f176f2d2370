"""3D meshes and energies: finite-difference checks and closed-form checks."""
import numpy as np
import pytest

from gripper_sim.core.energies import Gravity
from gripper_sim.core3d.energies import (EnclosedVolumePressure, HingeBending, Membrane,
                                         NeoHookeanTets, dihedral_angles)
from gripper_sim.core3d.energies.quadratic_tets import QuadraticNeoHookeanTets
from gripper_sim.core3d.meshes import (TET10_EDGES, body_surface, enclosed_volume,
                                       geodesic_sphere, hinges, signed_volumes)

from helpers import kernel_evaluation
from reference_energies2d import dense_hessian
from reference_energies3d import neohookean_von_mises, reference_evaluation
from reference_solver import reference_route

RNG = np.random.default_rng(7)
RADIUS = 0.03


def _perturbed(x0, scale):
    return (x0 + RNG.normal(scale=scale, size=x0.shape)).ravel()


def _cube_tets():
    """Five positively oriented tetrahedra of a 2 cm cube (no mesher needed)."""
    corners = 0.02 * np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)],
                              dtype=float)
    tets = np.array([[0, 1, 2, 4], [3, 2, 1, 7], [5, 4, 7, 1], [6, 7, 4, 2],
                     [1, 2, 4, 7]])
    vol = signed_volumes(corners, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    return corners, tets


def _cube_tets10():
    """The five cube tetrahedra as 10-node ones (corners, then the edge midpoints in the
    order of ``meshes.TET10_EDGES``), midpoints shared between neighbours."""
    corners, tets = _cube_tets()
    points = list(corners)
    mids = {}
    rows = []
    for tet in tets:
        row = list(tet)
        for i, j in TET10_EDGES:
            key = tuple(sorted((tet[i], tet[j])))
            if key not in mids:
                mids[key] = len(points)
                points.append(0.5 * (corners[key[0]] + corners[key[1]]))
            row.append(mids[key])
        rows.append(row)
    return np.array(points), np.array(rows)


def _energies():
    sphere = geodesic_sphere(2)
    x0 = RADIUS * sphere.positions
    tri = sphere.triangles
    corners, tets = _cube_tets()
    points10, tets10 = _cube_tets10()
    return [
        ('membrane', Membrane(tri, x0, 10e6, 0.4, 5e-4), _perturbed(x0, 1e-3)),
        ('hinge-bending', HingeBending(hinges(tri), x0, 1e-4), _perturbed(x0, 1e-3)),
        ('volume-pressure', EnclosedVolumePressure(tri, enclosed_volume(x0, tri), 3e4, 3e6),
         _perturbed(x0, 1e-3)),
        ('neo-hookean-tets', NeoHookeanTets(tets, corners, 2e6, 0.38),
         _perturbed(corners, 1e-3)),
        ('gravity', Gravity(np.full(len(x0), 0.01), 9.81, dim=3), _perturbed(x0, 1e-3)),
        ('quadratic-tets', QuadraticNeoHookeanTets(tets10, points10, 2e6, 0.38),
         _perturbed(points10, 5e-4)),
    ]


CASES = _energies()
IDS = [c[0] for c in CASES]


@pytest.mark.parametrize('name,energy,q', CASES, ids=IDS)
def test_gradient_matches_central_differences(name, energy, q):
    h = 1e-7
    grad = energy.gradient(q)
    fd = np.array([(energy.value(q + h * e) - energy.value(q - h * e)) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(grad)) > 1e-6, 'gradient is trivially zero'
    assert np.max(np.abs(grad - fd)) <= 1e-6 * np.max(np.abs(grad))


@pytest.mark.parametrize('name,energy,q', CASES[:4], ids=IDS[:4])
def test_numpy_reference_hessian_matches_central_differences(name, energy, q):
    """The references the kernels are compared with are right themselves."""
    h = 1e-7
    hess = dense_hessian(reference_evaluation(energy, q), q.size)
    fd = np.array([(reference_evaluation(energy, q + h * e, False).gradient
                    - reference_evaluation(energy, q - h * e, False).gradient) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(hess)) > 1e-3, 'Hessian is trivially zero'
    assert np.max(np.abs(hess - fd)) <= 1e-6 * np.max(np.abs(hess))
    assert np.allclose(hess, hess.T, atol=1e-9 * np.max(np.abs(hess)))


@pytest.mark.parametrize('name,energy,q', CASES, ids=IDS)
def test_numba_kernel_matches_the_numpy_reference(name, energy, q):
    """Each energy's kernel (its one implementation, through ``evaluate_into`` and the
    triplet form ``evaluate``) gives the value, gradient and Hessian of the independent
    numpy derivation in test/reference_energies3d.py."""
    value, grad, hess = kernel_evaluation(energy, q)
    reference = reference_evaluation(energy, q)
    assert value == pytest.approx(reference.value, rel=1e-12, abs=1e-18)
    assert energy.value(q) == pytest.approx(value, rel=1e-12, abs=1e-18)
    ref_grad = reference.gradient
    assert np.max(np.abs(ref_grad)) > 0
    assert np.max(np.abs(grad - ref_grad)) <= 1e-12 * np.max(np.abs(ref_grad))
    ref_hess = dense_hessian(reference, q.size)
    assert np.max(np.abs(hess - ref_hess)) <= 1e-12 * max(np.max(np.abs(ref_hess)), 1.0)
    assert np.max(np.abs(energy.hessian(q) - ref_hess)) <= 1e-12 * max(
        np.max(np.abs(ref_hess)), 1.0)
    value_only, grad_only, untouched = kernel_evaluation(energy, q, hessian=False)
    assert value_only == value and np.array_equal(grad_only, grad)
    assert not np.any(untouched)
    triplets = energy.evaluate(q, hessian=False)
    assert triplets.value == value and np.array_equal(triplets.gradient, grad)


@pytest.mark.parametrize('name,energy,q', CASES[:4] + CASES[5:], ids=IDS[:4] + IDS[5:])
def test_numba_kernel_hessian_matches_central_differences_of_its_gradient(name, energy, q):
    h = 1e-7
    _, _, hess = kernel_evaluation(energy, q)
    fd = np.array([(kernel_evaluation(energy, q + h * e, False)[1]
                    - kernel_evaluation(energy, q - h * e, False)[1]) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(hess)) > 1e-3, 'Hessian is trivially zero'
    assert np.max(np.abs(hess - fd)) <= 1e-6 * np.max(np.abs(hess))


def test_numba_von_mises_matches_the_numpy_reference():
    corners, tets = _cube_tets()
    flesh = NeoHookeanTets(tets, corners, 2e6, 0.38)
    q = _perturbed(corners, 2e-3)
    ref = neohookean_von_mises(flesh, q)
    assert np.all(ref > 1e3)
    assert np.allclose(flesh.von_mises(q), ref, rtol=1e-12, atol=0.0)


def test_numba_tet_kernel_rejects_an_inverted_element_without_adding_anything():
    corners, tets = _cube_tets()
    flesh = NeoHookeanTets(tets, corners, 2e6, 0.38)
    mirrored = (corners * np.array([-1.0, 1.0, 1.0])).ravel()
    value, grad, hess = kernel_evaluation(flesh, mirrored)
    assert value == np.inf and not np.any(grad) and not np.any(hess)


def test_energies_vanish_at_rest_and_under_rigid_motion():
    sphere = geodesic_sphere(2)
    x0 = RADIUS * sphere.positions
    tri = sphere.triangles
    corners, tets = _cube_tets()
    angle = 0.7
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                    [0, 0, 1]])
    shift = np.array([0.01, -0.02, 0.03])
    for energy, rest in ((Membrane(tri, x0, 10e6, 0.4, 5e-4), x0),
                         (HingeBending(hinges(tri), x0, 1e-4), x0),
                         (NeoHookeanTets(tets, corners, 2e6, 0.38), corners)):
        scale = energy.value((1.01 * rest).ravel())
        assert scale > 0
        for x in (rest, rest @ rot.T + shift):
            assert energy.value(x.ravel()) == pytest.approx(0.0, abs=1e-12 * scale + 1e-18)
            assert np.max(np.abs(energy.gradient(x.ravel()))) < 1e-9


def test_inverted_tetrahedron_has_infinite_energy():
    corners, tets = _cube_tets()
    flesh = NeoHookeanTets(tets, corners, 2e6, 0.38)
    mirrored = corners * np.array([-1.0, 1.0, 1.0])
    assert flesh.value(mirrored.ravel()) == np.inf


def _flat_sheet(n=24, a=1e-3):
    """A regular (equilateral) triangle sheet in the x-y plane, n x n vertices."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing='ij')
    x = a * (i + 0.5 * (j % 2))
    y = a * np.sqrt(3) / 2 * j
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    tris = []
    for jj in range(n - 1):
        for ii in range(n - 1):
            a0, a1, b0, b1 = idx[ii, jj], idx[ii + 1, jj], idx[ii, jj + 1], idx[ii + 1, jj + 1]
            if jj % 2 == 0:
                tris += [(a0, a1, b0), (a1, b1, b0)]
            else:
                tris += [(a0, a1, b1), (a0, b1, b0)]
    return pts, np.array(tris)


def _interior_hinges(tris):
    t = np.asarray(tris)
    edges = {}
    for k, tri in enumerate(t):
        for m in range(3):
            edges.setdefault((tri[m], tri[(m + 1) % 3]), (k, tri[(m + 2) % 3]))
    out = []
    for (a, b), (_, c) in edges.items():
        if (b, a) in edges and a < b:
            out.append((a, b, c, edges[(b, a)][1]))
    return np.array(out)


@pytest.mark.parametrize('direction', ['x', 'y'])
def test_hinge_energy_of_a_rolled_sheet_matches_plate_bending(direction):
    """A flat sheet rolled to curvature kappa stores D kappa^2 / 2 per unit area."""
    pts, tris = _flat_sheet()
    h = _interior_hinges(tris)
    d = 2e-4
    energy = HingeBending(h, pts, d)
    kappa = 5.0  # 1/m: 0.2 m radius, the sheet spans 24 mm
    axis = 0 if direction == 'x' else 1
    s = pts[:, axis]
    rolled = pts.copy()
    rolled[:, axis] = np.sin(kappa * s) / kappa
    rolled[:, 2] = (1 - np.cos(kappa * s)) / kappa
    # the area the hinges represent: a third of each of their two triangles
    p = pts[tris]
    tri_area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    hinge_area = len(h) * 2 * tri_area.mean() / 3
    expected = 0.5 * d * kappa ** 2 * hinge_area
    assert energy.value(rolled.ravel()) == pytest.approx(expected, rel=0.03)


def test_geodesic_sphere_counts_and_convexity():
    for f in (1, 3, 8):
        mesh = geodesic_sphere(f)
        assert len(mesh.positions) == 10 * f * f + 2
        assert len(mesh.triangles) == 20 * f * f
        assert np.allclose(np.linalg.norm(mesh.positions, axis=1), 1.0)
        theta = dihedral_angles(mesh.positions, hinges(mesh.triangles))
        assert np.all(theta > 0), 'outward orientation: every hinge of a sphere is convex'


@pytest.mark.parametrize('refinement', [1.0, 0.3])
def test_graded_sphere_keeps_orientation_and_refines_the_poles(refinement):
    mesh = body_surface('sphere', 6, refinement, radius=RADIUS)
    x, tri = mesh.positions, mesh.triangles
    assert enclosed_volume(x, tri) == pytest.approx(4 / 3 * np.pi * RADIUS ** 3, rel=0.03)
    theta = dihedral_angles(x, hinges(tri))
    assert np.all(theta > -1e-9), 'a convex triangulation (flat where points are co-circular)'
    p = x[tri]
    centre = p.mean(axis=1)
    size = np.linalg.norm(p[:, 1] - p[:, 0], axis=1)
    near_pole = np.argsort(-np.abs(centre[:, 0]))[:24]  # the fans around the two poles
    ratio = size[near_pole].mean() / size.mean()
    if refinement == 1.0:
        assert 0.8 < ratio < 1.2
    else:
        assert ratio < 0.6


def test_ellipsoid_and_revolution_bodies():
    axes = (0.03, 0.025, 0.02)
    mesh = body_surface('ellipsoid', 6, 1.0, radius=0.03, semi_axes=axes)
    extent = np.ptp(mesh.positions, axis=0) / 2
    assert extent[0] == pytest.approx(axes[0], rel=1e-9)  # vertices on the jaw axis
    assert np.allclose(extent[1:], axes[1:], rtol=0.02)
    assert enclosed_volume(mesh.positions, mesh.triangles) == pytest.approx(
        4 / 3 * np.pi * np.prod(axes), rel=0.03)
    # a cone-topped cylinder: r = 10 mm for z in [0, 20] mm, apex at z = 30 mm
    profile = np.array([[0, 0], [0.01, 0], [0.01, 0.02], [0, 0.03]])
    body = body_surface('revolution', 8, 1.0, radius=0.01, profile=profile)
    volume = np.pi * 0.01 ** 2 * 0.02 + np.pi * 0.01 ** 2 * 0.01 / 3
    assert enclosed_volume(body.positions, body.triangles) == pytest.approx(volume, rel=0.05)
    assert np.ptp(body.positions[:, 2]) == pytest.approx(0.03, rel=1e-6)


def test_strawberry_outline_revolved_has_the_pappus_volume():
    """The 3D body of a 2D outline is that outline revolved about z: its volume is
    2 pi x_c A of the right half-outline (Pappus), x_c its centroid's distance from the axis."""
    from gripper_sim.configuration import load_config
    from gripper_sim.geometry import shapes
    from gripper_sim.core3d.fruit import _meridian, body_from_config
    config = load_config(fruit='strawberry', overrides=['dimension=3', 'fruit.shape.angle=0',
                                                       'fruit.mesh.subdivisions=10',
                                                       'fruit.mesh.jaw_refinement=1'])
    outline = shapes.outline_from_config(config)
    half = _meridian(outline)  # (r, z) from the bottom to the top, both ends on the axis
    r, z = half[:, 0], half[:, 1]
    # area and first moment about the axis of the region between the meridian and the axis
    nr, nz = np.roll(r, -1), np.roll(z, -1)
    cross = r * nz - nr * z
    area = 0.5 * np.sum(cross)
    moment = np.sum((r + nr) * cross) / 6.0
    pappus = abs(2 * np.pi * moment)
    assert abs(area) > 0
    body = body_from_config(config)
    assert enclosed_volume(body.positions, body.triangles) == pytest.approx(pappus, rel=0.03)
    assert np.all(dihedral_angles(body.positions, hinges(body.triangles)) > -np.pi / 2)


@pytest.mark.slow
@pytest.mark.parametrize('model', [
    ['fruit.model=shell', 'fruit.mesh.subdivisions=4'],
    ['fruit.model=solid', 'fruit.skin.enabled=false', 'fruit.mesh.subdivisions=3',
     'fruit.mesh.max_tet_volume=1e-6'],
    ['fruit.model=solid', 'fruit.skin.enabled=false', 'fruit.mesh.subdivisions=3',
     'fruit.mesh.max_tet_volume=1e-6', 'fruit.mesh.order=2']],
    ids=['shell', 'solid', 'solid-quadratic'])
def test_fast_solver_follows_the_numpy_reference_path(model):
    """The same grasp on the solver (kernels into a fixed sparse pattern, CG on a kept
    LU, warm-started contact passes) and on the test reference (``reference_route``: the
    same kernels as triplets, one LU per Newton iteration): the same contact sets and, to
    the Newton tolerance, the same motion. The jaws close in position mode (one solve per
    step): in force mode the drive re-solves a step until the force meets its command,
    and which solves it takes may differ between the paths by the Newton tolerance."""
    from gripper_sim.configuration import load_config
    from gripper_sim.workflows.factory import make_simulation
    config = load_config(overrides=['dimension=3', 'sim.dt=0.01'] + model)
    runs = []
    steps = None
    for fast in (True, False):
        sim = make_simulation(config)
        if not fast:
            reference_route(sim)
        sim.command_gap(0.0615)   # 1 mm into the 63.5 mm apple on each side
        results = [sim.step()]
        while steps is None and results[-1].grip_force < 0.5 and len(results) < 400:
            results.append(sim.step())
        # the fast run: 20 more steps once gripping; the reference: as many as it
        for _ in range(20 if steps is None else steps - 1):
            results.append(sim.step())
        steps = len(results)
        runs.append(results)
    fast_run, reference = runs
    assert max(r.grip_force for r in reference) > 1.0, 'the jaws never gripped'
    tol = config['sim.newton_tolerance'] * config['sim.dt']  # m
    # forces follow the positions through the contact stiffness (~1e3 N/m): 10 tol of
    # position is 1e-4 N of force
    force_tol = 1e3 * 10 * tol
    for a, b in zip(fast_run, reference):
        assert np.array_equal(a.contact_obstacle, b.contact_obstacle)
        assert np.max(np.abs(a.positions - b.positions)) < 10 * tol
        assert a.grip_force == pytest.approx(b.grip_force, rel=1e-3, abs=force_tol)
