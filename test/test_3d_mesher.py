"""The layered tetrahedral mesher of the 3D solid fruit: valid, conforming, surface kept."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core3d import layered_mesher, meshes
from gripper_sim.core3d.fruit import body_from_config
from gripper_sim.errors import ConfigError

BODIES = {
    'apple-uniform': ('apple', ['fruit.mesh.subdivisions=6', 'fruit.mesh.jaw_refinement=1']),
    'apple-rings': ('apple', ['fruit.mesh.subdivisions=3', 'fruit.mesh.jaw_refinement=0.25']),
    'strawberry': ('strawberry', ['fruit.mesh.subdivisions=5']),
    'egg-tilted': ('apple', ['fruit.shape.type=egg', 'fruit.shape.taper=0.3',
                             'fruit.shape.height=0.08', 'fruit.shape.angle=30',
                             'fruit.shape.width=0.05', 'fruit.mesh.subdivisions=4']),
}


def _surface(name):
    fruit, overrides = BODIES[name]
    config = load_config(fruit=fruit, overrides=['dimension=3', 'fruit.model=solid']
                         + overrides)
    return body_from_config(config)


def _faces(tets):
    """(4 n, 3) the faces of linear tetrahedra, each outward from its tetrahedron."""
    return np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]],
                           tets[:, [0, 2, 1]]])


def _rotated_to_smallest_first(tris):
    first = np.argmin(tris, axis=1)
    return np.stack([np.take_along_axis(tris, ((first + k) % 3)[:, None], 1)[:, 0]
                     for k in range(3)], axis=1)


@pytest.mark.parametrize('name', sorted(BODIES))
@pytest.mark.parametrize('layers', [0, 1, 2, 3])
def test_layered_mesh_is_valid_conforming_and_keeps_the_surface(name, layers):
    surface = _surface(name)
    nodes, tets = layered_mesher.layered_tetrahedra(surface.positions, surface.triangles,
                                                    layers)
    n_s, n_tri = len(surface.positions), len(surface.triangles)
    assert np.array_equal(nodes[:n_s], surface.positions)
    assert len(nodes) == n_s * (layers + 1) + 1 and len(tets) == n_tri * (3 * layers + 1)
    quality = layered_mesher.mesh_quality(nodes, tets)
    assert quality.min_volume > 0
    assert quality.min_dihedral > 5.0 and quality.max_dihedral < 175.0
    # every face is either shared by two tetrahedra in opposite senses (conforming: the
    # prisms' quadrilaterals are cut the same way from both sides) or a surface triangle
    faces = _rotated_to_smallest_first(_faces(tets))
    keys = {tuple(f) for f in faces}
    assert len(keys) == len(faces)
    boundary = {f for f in keys if (f[0], f[2], f[1]) not in keys}
    assert boundary == {tuple(f) for f in _rotated_to_smallest_first(surface.triangles)}
    # the tetrahedra fill exactly what the surface encloses
    volume = meshes.signed_volumes(nodes, tets).sum()
    enclosed = meshes.enclosed_volume(surface.positions, surface.triangles)
    assert volume == pytest.approx(enclosed, rel=1e-12)


def test_layers_are_graded_and_stay_inside_their_rays():
    radius = np.array([0.03, 0.03, 0.004])
    spacing = np.array([0.001, 0.006, 0.006])
    rho = layered_mesher.layer_radii(radius, spacing, 3)
    depth = -np.diff(rho, axis=0)
    assert np.allclose(depth[0, :2], layered_mesher.FIRST_LAYER * spacing[:2])
    assert np.allclose(depth[1, 0] / depth[0, 0], layered_mesher.LAYER_GROWTH)
    assert np.all(rho > 0) and np.all(depth > 0)
    # no layer deeper than its edges are long (the surface's shrunk toward the centre)
    width = spacing * rho[:-1] / radius
    assert np.all(depth <= layered_mesher.MAX_LAYER_ASPECT * width + 1e-15)
    assert depth[2, 0] < depth[1, 0] * layered_mesher.LAYER_GROWTH
    # the short ray's layers are capped at a fraction of what is left of it
    assert np.all(depth[:, 2] <= layered_mesher.MAX_LAYER_FRACTION * rho[:-1, 2] + 1e-15)
    assert depth[0, 2] == pytest.approx(layered_mesher.MAX_LAYER_FRACTION * radius[2])


def test_quadratic_mesh_puts_shared_midpoint_nodes_on_every_edge():
    surface = _surface('apple-rings')
    linear = meshes.tetrahedralize(surface)
    quadratic = meshes.tetrahedralize(surface, order=2)
    n = len(linear.positions)
    assert np.array_equal(quadratic.tetrahedra[:, :4], linear.tetrahedra)
    assert np.array_equal(quadratic.positions[:n], linear.positions)
    x = quadratic.positions
    for k, (i, j) in enumerate(meshes.TET10_EDGES):
        mid = quadratic.tetrahedra[:, 4 + k]
        corners = quadratic.tetrahedra[:, [i, j]]
        assert np.allclose(x[mid], 0.5 * (x[corners[:, 0]] + x[corners[:, 1]]), atol=1e-15)
    edges = meshes.surface_edges(np.concatenate([linear.tetrahedra[:, [a, b, c]] for a, b, c
                                                 in ((0, 1, 2), (0, 1, 3), (1, 2, 3))]))
    assert len(x) == n + len(edges)  # one node per edge: neighbours share it
    assert len(quadratic.triangles) == 4 * len(surface.triangles)
    assert meshes.enclosed_volume(x, quadratic.triangles) == pytest.approx(
        meshes.enclosed_volume(surface.positions, surface.triangles), rel=1e-12)
    on_skin = np.unique(quadratic.triangles)
    assert np.array_equal(np.sort(quadratic.surface_nodes), on_skin)


def test_largest_volume_adds_layers_until_every_tetrahedron_is_below_it():
    surface = _surface('apple-uniform')
    default = meshes.tetrahedralize(surface)
    assert len(default.positions) == len(surface.positions) * (meshes.DEFAULT_LAYERS + 1) + 1
    largest = meshes.signed_volumes(default.positions, default.tetrahedra).max()
    for bound in (3.0 * largest, 0.8 * largest):
        mesh = meshes.tetrahedralize(surface, bound)
        assert meshes.signed_volumes(mesh.positions, mesh.tetrahedra).max() <= bound
    assert len(meshes.tetrahedralize(surface, 3.0 * largest).positions) < len(default.positions)
    assert len(meshes.tetrahedralize(surface, 0.8 * largest).positions) > len(default.positions)


def test_unreachable_largest_volume_names_the_key():
    surface = _surface('apple-uniform')
    with pytest.raises(ConfigError, match=r"fruit\.mesh\.max_tet_volume"):
        meshes.tetrahedralize(surface, 1e-12)


def test_body_not_star_shaped_about_the_centre_is_a_config_error():
    surface = _surface('apple-uniform')
    outside = np.array([0.1, 0.0, 0.0])
    with pytest.raises(ConfigError, match='star-shaped'):
        layered_mesher.layered_tetrahedra(surface.positions, surface.triangles, 1, outside)


def test_star_centre_of_an_off_centre_body_sees_every_triangle():
    surface = _surface('strawberry')
    shifted = surface.positions + np.array([0.01, -0.02, 0.005])
    centre = layered_mesher.star_centre(shifted, surface.triangles)
    p = shifted[surface.triangles] - centre
    assert np.all(np.einsum('ij,ij->i', p[:, 0], np.cross(p[:, 1], p[:, 2])) > 0)
