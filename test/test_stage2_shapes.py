"""Shapes: ellipse stiffness along its axes, outlines round-tripping through config and
meshing without inverted elements, and clear errors for bad outlines."""
import numpy as np
import pytest
import yaml

from gripper_sim.configuration import load_config, to_yaml
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.mesh import boundary_edges, mesh_outline, triangle_areas
from gripper_sim.errors import ConfigError
from gripper_sim.geometry.shapes import crossing_segments, outline_from_config, polygon_area
from helpers import QUASI_STATIC
from gripper_sim.core.simulation import Simulation
from test_cli_offline import gripper_sim

STRAWBERRY = [[0.0, 0.016], [0.008, 0.0165], [0.0135, 0.014], [0.0155, 0.008], [0.0145, 0.0],
              [0.011, -0.009], [0.006, -0.015], [0.0, -0.018], [-0.006, -0.015],
              [-0.011, -0.009], [-0.0145, 0.0], [-0.0155, 0.008], [-0.0135, 0.014],
              [-0.008, 0.0165]]


def _ellipse_squeeze(angle, travel=None, force=None):
    """Solid elliptical disk, axes 80 x 64 mm, turned by ``angle`` deg, squeezed by rigid
    flat jaws quasi-statically to a plate travel or a force."""
    config = load_config(overrides=QUASI_STATIC + [
        'fruit.model=solid', 'fruit.skin.enabled=false', 'fruit.shape.type=ellipse',
        'fruit.shape.diameter=0.08', 'fruit.shape.height=0.064', f'fruit.shape.angle={angle}',
        'fruit.nodes=96', 'fruit.flesh.youngs_modulus=1e6', 'fruit.flesh.poisson_ratio=0.3'])
    sim = Simulation(config)
    width = sim.fruit.rest_width
    sim = Simulation(dict(config, **{'gripper.initial_gap': width + 1e-4}))
    if travel is not None:
        sim.command_gap(width - travel, speed=travel / 0.5)
    else:
        sim.command_force(force, speed=0.004)
    return sim, sim.run(1.5)


def test_ellipse_is_stiffer_squeezed_along_its_minor_axis():
    """Same plate travel: the blunt ends of the minor axis (radius of curvature a^2/b =
    50 mm) and the shorter load path give more force than the sharp ends of the major
    axis (b^2/a = 25.6 mm); measured: about 1.2 times."""
    _, major = _ellipse_squeeze(0.0, travel=0.0015)
    _, minor = _ellipse_squeeze(90.0, travel=0.0015)
    assert minor.grip_force > 1.1 * major.grip_force > 0


def test_ellipse_at_equal_force_compresses_less_and_wider_along_its_minor_axis():
    """Equal force: less approach along the minor axis (stiffer), and a wider contact
    (Hertz: the half-width grows as sqrt(R) with the radius of curvature R)."""
    _, major = _ellipse_squeeze(0.0, force=2.0)
    _, minor = _ellipse_squeeze(90.0, force=2.0)
    assert minor.grip_force == pytest.approx(major.grip_force, rel=1e-3)
    assert minor.deformation.compression < 0.9 * major.deformation.compression
    assert minor.deformation.contact_length > major.deformation.contact_length


def test_turned_ellipse_swaps_its_extent():
    base = {'fruit.shape.type': 'ellipse', 'fruit.shape.diameter': 0.08,
            'fruit.shape.height': 0.05, 'fruit.model': 'solid'}
    flat = outline_from_config(load_config(overrides=base))
    upright = outline_from_config(load_config(overrides=dict(base, **{'fruit.shape.angle': 90})))
    assert np.ptp(flat[:, 0]) == pytest.approx(0.08, rel=1e-3)
    assert np.ptp(upright[:, 0]) == pytest.approx(0.05, rel=1e-3)
    assert np.ptp(upright[:, 1]) == pytest.approx(0.08, rel=1e-3)
    assert polygon_area(upright) == pytest.approx(polygon_area(flat))


@pytest.mark.parametrize('kind', ['points', 'spline'])
def test_outline_round_trips_through_config_and_meshes_cleanly(kind, tmp_path):
    overrides = {'fruit.model': 'solid', 'fruit.shape.type': kind,
                 'fruit.shape.points': STRAWBERRY, 'fruit.shape.angle': 30.0}
    config = load_config(overrides=overrides)
    path = tmp_path / 'fruit.yaml'
    path.write_text(to_yaml(config))
    again = load_config(config_file=path)
    assert again == config
    first, second = build_fruit(config), build_fruit(again)
    assert np.array_equal(first.rest_positions, second.rest_positions)
    # the outline passes through (rotated) control points for a spline, and has the area
    outline = first.rest_positions[first.surface]
    assert len(outline) == config['fruit.nodes']
    assert crossing_segments(outline) is None
    nodes, tri = first.rest_positions, first.triangles
    assert np.all(triangle_areas(nodes, tri) > 0), 'inverted triangles'
    n = len(outline)
    assert boundary_edges(tri) == {tuple(sorted((i, (i + 1) % n))) for i in range(n)}
    assert triangle_areas(nodes, tri).sum() == pytest.approx(polygon_area(outline), rel=1e-9)
    control = np.array(STRAWBERRY)
    assert abs(polygon_area(outline)) == pytest.approx(abs(polygon_area(control)), rel=0.08)


@pytest.mark.parametrize('outline', [
    'ellipse-long', 'egg', 'bean'])
def test_mesher_follows_convex_and_concave_outlines(outline):
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    if outline == 'ellipse-long':
        points = np.stack([0.05 * np.cos(t), 0.015 * np.sin(t)], axis=1)
    elif outline == 'egg':
        points = np.stack([0.03 * np.cos(t) * (1 - 0.3 * np.sin(t)), 0.04 * np.sin(t)], axis=1)
    else:  # a kidney bean: concave on one side
        r = 0.03 * (1 - 0.35 * np.cos(t) ** 8 * (np.cos(t) > 0))
        points = np.stack([r * np.cos(t), 0.6 * r * np.sin(t)], axis=1)
    nodes, tri = mesh_outline(points)
    assert np.all(triangle_areas(nodes, tri) > 0)
    assert triangle_areas(nodes, tri).sum() == pytest.approx(polygon_area(points), rel=1e-9)
    assert len(nodes) > len(points)  # interior nodes were placed


@pytest.mark.parametrize('overrides,message', [
    ({'fruit.shape.type': 'points', 'fruit.model': 'solid',
      'fruit.shape.points': [[0, 0], [0.02, 0.02], [0.02, 0], [0, 0.02]]}, 'crosses itself'),
    ({'fruit.shape.type': 'spline', 'fruit.model': 'solid',
      'fruit.shape.points': [[0, 0], [0.02, 0]]}, 'at least 4'),
    ({'fruit.shape.type': 'points', 'fruit.model': 'solid',
      'fruit.shape.points': [[0, 0], [0.02, 0], [0.02, 0], [0, 0.02]]}, 'coincide'),
    ({'fruit.shape.type': 'points', 'fruit.model': 'solid',
      'fruit.shape.points': [[0, 0], [0.01, 0], [0.02, 0]]}, 'no area'),
    ({'fruit.shape.type': 'spline', 'fruit.model': 'solid'}, 'is empty'),
    ({'fruit.shape.type': 'points', 'fruit.model': 'solid',
      'fruit.shape.points': 'nonsense'}, 'pairs'),
    ({'fruit.shape.type': 'ellipse', 'fruit.shape.height': 0.05}, 'shell model'),
])
def test_bad_outline_is_refused_naming_the_key(overrides, message):
    with pytest.raises(ConfigError, match=message) as info:
        load_config(overrides=overrides)
    assert "'fruit.shape." in str(info.value)


def test_self_intersecting_outline_from_the_cli_is_a_clear_error(tmp_path):
    path = tmp_path / 'bowtie.yaml'
    path.write_text(yaml.safe_dump({'fruit': {
        'model': 'solid', 'shape': {'type': 'spline', 'points': [
            [0, 0], [0.03, 0.03], [0.03, 0], [0, 0.03]]}}}))
    run = gripper_sim('squeeze', '--config', str(path), '--to-force', '1')
    assert run.returncode == 2
    assert "error: config key 'fruit.shape.points'" in run.stderr
    assert 'crosses itself' in run.stderr and 'Traceback' not in run.stderr


def _first_crossing_by_every_pair(points):
    """The reference: every pair of non-adjacent edges, in order, by orientations (a
    touching endpoint counts)."""
    p = np.asarray(points, float)
    n = len(p)
    eps = 1e-12 * float(np.ptp(p)) ** 2

    def orient(o, u, v):
        return (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0])

    def on(o, u, v):
        return (min(o[0], u[0]) <= v[0] <= max(o[0], u[0])
                and min(o[1], u[1]) <= v[1] <= max(o[1], u[1]))

    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            a, b, c, d = p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]
            d1, d2, d3, d4 = orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b)
            if (d1 * d2 < 0 and abs(d1) > eps and abs(d2) > eps
                    and d3 * d4 < 0 and abs(d3) > eps and abs(d4) > eps):
                return i, j
            if ((abs(d1) <= eps and on(a, b, c)) or (abs(d2) <= eps and on(a, b, d))
                    or (abs(d3) <= eps and on(c, d, a)) or (abs(d4) <= eps and on(c, d, b))):
                return i, j
    return None


def test_the_self_crossing_sweep_finds_the_first_pair_every_pair_would():
    rng = np.random.default_rng(7)
    for trial in range(600):
        n = int(rng.integers(3, 30))
        if trial % 3 == 0:
            points = rng.random((n, 2))                         # mostly crossing
        elif trial % 3 == 1:
            points = rng.integers(0, 4, (n, 2)).astype(float)   # collinear, touching
        else:
            angle = np.sort(rng.random(n)) * 2 * np.pi          # mostly simple
            points = np.c_[np.cos(angle), np.sin(angle)] * (1 + 0.3 * rng.random(n))[:, None]
        assert crossing_segments(points) == _first_crossing_by_every_pair(points), points
