"""The 3D Fin Ray's self-contact: its shells (beams and ribs) never cross each other.

As in 2D (test_fin_ray_self_contact.py): the default Fin Ray 10 mm deep, extruded into
shells in 2 slices, pressed over the middle third of its front beam across its width
(the load ramped over 100 increments of 1 ms, each starting at rest, then held for 100:
an overdamped motion that follows the finger's snap-through) folds its front beam onto
the members behind it. The 3D finger is 1 / (1 - nu^2) stiffer in bending than the 2D
one (plate modulus, test_fin_ray_3d.py): its members cross at 15 N (not at 12 N, where
the 2D finger's do). Without self-contact they cross; with it
(``FingerBody3D.self_contact``: the barrier between a vertex and a triangle, or two
edges, of the finger's shells that share no node) they touch and never cross, in any
section and as surfaces (ipctk's intersection test), at every increment.
"""
import ipctk
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.barrier import BarrierContact
from gripper_sim.core.fin_ray import fin_ray_body
from gripper_sim.core.finger_statics import static_equilibrium
from gripper_sim.core3d.mesh_geometry import surface_edges
from gripper_sim.core3d.rod_extrusion import extruded_rod_body
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.core3d.soft_fingers3d import fin_ray_body3d
from gripper_sim.geometry.finger_materials import MATERIALS
from test_fin_ray import _geometry, _press
from test_fin_ray_3d import _line_load
from test_fin_ray_self_contact import SETTINGS, crossings, smallest_gap

GRIP = 15.0
DEPTH = 0.01
SLICES = 2


def _body():
    """(the 2D section, its 3D extrusion) of the 10 mm deep default finger."""
    section = fin_ray_body(_geometry(depth=DEPTH), MATERIALS['tpu'])
    return section, extruded_rod_body(section, DEPTH, SLICES)


def _sections(section, x: np.ndarray) -> list[np.ndarray]:
    """The (n2, 2) m (x, z) positions of each slice's copy of the section in ``x``."""
    n = section.n_nodes
    return [x[k * n:(k + 1) * n][:, [0, 2]] for k in range(x.shape[0] // n)]


def _intersecting(body, x: np.ndarray) -> bool:
    """Whether any two of the shells' triangles and edges that share no node intersect
    at positions ``x`` (n, 3) m."""
    nodes = np.unique(body.shell_triangles)
    local = -np.ones(body.n_nodes, np.int64)
    local[nodes] = np.arange(nodes.size)
    triangles = local[body.shell_triangles]
    mesh = ipctk.CollisionMesh(np.asfortranarray(body.rest_positions[nodes]),
                               np.asfortranarray(surface_edges(triangles).astype(np.int32)),
                               np.asfortranarray(triangles.astype(np.int32)))
    return bool(ipctk.has_intersections(mesh, np.asfortranarray(x[nodes])))


def _fold(self_contact):
    """(crossings summed over the sections, whether the shells intersect: at each
    increment; the smallest gap in any section at the end m) of the pressed finger."""
    section, body = _body()
    forces2d, _ = _press(section, GRIP, 0.01)
    counts, intersecting = [], []

    def watch(x):
        counts.append(sum(crossings(s, section.rod_edges) for s in _sections(section, x)))
        intersecting.append(_intersecting(body, x))

    final = static_equilibrium(body, _line_load(section, body, forces2d), increments=100,
                               hold=100, step=1e-3, tolerance=1e-6, self_contact=self_contact,
                               on_increment=watch, elastic=body.elastic_energies())
    gap = min(smallest_gap(s, section.rod_edges) for s in _sections(section, final.positions))
    return counts, intersecting, gap


def test_without_self_contact_the_pressed_shells_cross():
    counts, intersecting, _ = _fold(None)
    assert counts[0] == 0 and not intersecting[0]
    assert max(counts) > 0 and any(intersecting)


def test_with_self_contact_the_shells_touch_and_never_cross(monkeypatch):
    answers = []
    quiet = BarrierContact.quiet

    def recorded(barrier, *args):
        answers.append(quiet(barrier, *args))
        return answers[-1]

    monkeypatch.setattr(BarrierContact, 'quiet', recorded)
    counts, intersecting, gap = _fold(SETTINGS)
    assert len(counts) == 200
    assert max(counts) == 0 and not any(intersecting)
    assert 0 < gap < 1e-5, 'folded onto the members behind it, not through them'
    # while the members stay apart the barrier's work is skipped (its quiet region);
    # once they come near it is done
    assert any(answers) and not all(answers)


def test_a_quiet_self_contact_is_quiet_whatever_the_finger_s_translation():
    _, body = _body()
    barrier = body.self_contact(SETTINGS)
    x = body.rest_positions
    barrier.begin_step(x, [], [], 1e-3)
    assert barrier.quiet(x.ravel())
    assert barrier.quiet((x + [0.01, -0.02, 0.03]).ravel())
    # one node moved by a millimetre against the others: beyond the region's reach (half
    # the smallest gap between two members, 0.38 mm here, less dhat: 0.19 mm)
    moved = x.copy()
    moved[body.tip_node, 0] += 1e-3
    assert not barrier.quiet(moved.ravel())


def test_the_finger_at_rest_feels_no_self_contact():
    _, body = _body()
    barrier = body.self_contact(SETTINGS)
    x = body.rest_positions
    barrier.begin_step(x, [], [], 1e-3)
    evaluation = barrier.evaluate(x.ravel())
    assert evaluation.value == 0.0 and not np.any(evaluation.gradient)
    assert barrier.min_distance(x) == np.inf
    assert not _intersecting(body, x)


def test_the_3d_simulation_gives_each_fin_ray_its_self_contact():
    sim = Simulation3D(load_config(overrides=['dimension=3', 'gripper.finger.type=fin_ray']))
    soft = sim._soft
    barrier = soft.self_contact
    assert barrier is not None and barrier in sim.solver.energies
    assert barrier.dimension == 3 and barrier.settings.dhat == SETTINGS.dhat
    first, m = sim.fruit.n_nodes, soft.body.n_nodes
    bodies = [set(body.nodes.tolist()) for body in barrier.bodies]
    shells = set(np.unique(soft.body.shell_triangles).tolist())
    assert bodies == [{first + i for i in shells}, {first + m + i for i in shells}]
    # the pattern's pairs stay within one finger
    pairs = barrier.pattern_pairs - first
    assert np.all((pairs[:, 0] < m) == (pairs[:, 1] < m))


def test_the_3d_solid_pad_has_no_self_contact():
    config = load_config(overrides=['dimension=3', 'gripper.finger.type=solid_pad'])
    sim = Simulation3D(config)
    assert sim._soft.self_contact is None
    assert fin_ray_body3d(load_config(overrides=[
        'dimension=3', 'gripper.finger.type=fin_ray'])).self_contact_settings is not None
