"""Deformable fingers in 3D (``core3d.soft_fingers3d``): the solid pad extruded over the jaw
width, in barrier contact with the 3D fruit.

- The mesh: positive tetrahedra, conforming (the boundary is the box's six faces), the
  mass the block's, the backing bonded and left out of the contact surface.
- The pad alone, closed form (small strain, linear isotropic elasticity; Timoshenko &
  Goodier, Theory of Elasticity, 3rd ed., sec. 3, Hooke's law): compressed by delta
  between two frictionless plates (uniaxial stress) the force is E A delta / t exactly
  (linear tetrahedra hold any homogeneous strain); with its sides held too (uniaxial
  strain) M A delta / t, M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) the constrained (P-wave)
  modulus; bonded to its backing and to the plate (the pad on its jaw against a sticking
  fruit) it lies between the two, every added constraint stiffening it (minimum
  potential energy).
- On the default (turgid shell) apple in force mode: no vertex of either body inside
  the other and no pair closer than 0 at any step, the grip force met, left and right
  symmetric. The fruit's contact area equals the rigid flat finger's at equal force
  (within the fruit mesh's resolution): a membrane under turgor p carries a contact
  pressure p wherever it lies against a face, so its area is F / p whatever presses it.
  On the solid apple (a Hertz-like contact) the pad's compliance spreads the contact.
"""
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gripper_sim.configuration import load_config
from gripper_sim.convert.messages import build_messages
from gripper_sim.core.solid_pad import block_body
from gripper_sim.core3d.energies import NeoHookeanTets
from gripper_sim.core3d.finger_body3d import extruded_body
from gripper_sim.core3d.mesh_geometry import signed_volumes
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.errors import ConfigError
from squeeze3d import assert_squeezed, finger_area_difference, squeeze

PAD_3D = ['dimension=3', 'gripper.finger.type=solid_pad']
T, H, W = 0.006, 0.04, 0.03
E, NU, RHO = 0.6e6, 0.45, 1080.0


def _pad(layers=3, rows=8, slices=6):
    return extruded_body(block_body('solid_pad', T, H, layers, rows, W, E, NU, RHO), W, slices)


def test_the_extruded_pad_is_a_conforming_tetrahedral_block():
    layers, rows, slices = 3, 8, 6
    body = _pad(layers, rows, slices)
    x = body.rest_positions
    assert body.n_nodes == (layers + 1) * (rows + 1) * (slices + 1)
    assert np.all(signed_volumes(x, body.tetrahedra) > 0)
    assert signed_volumes(x, body.tetrahedra).sum() == pytest.approx(T * H * W)
    assert body.masses.sum() == pytest.approx(RHO * T * H * W)
    assert np.ptp(x, axis=0) == pytest.approx([T, W, H])
    # the backing's nodes are bonded; the surface is the box's other five faces, two
    # triangles per cell face, wound outward
    assert np.all(x[body.base_nodes, 0] == 0.0)
    assert body.base_nodes.size == (rows + 1) * (slices + 1)
    faces = body.surface_triangles
    assert len(faces) == 2 * (rows * slices + 2 * layers * slices + 2 * layers * rows)
    p = x[faces]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    outward = p.mean(axis=1) - x.mean(axis=0)
    assert np.all(np.einsum('ij,ij->i', normals, outward) > 0)
    assert not np.any(np.all(np.isclose(p[:, :, 0], 0.0), axis=1))


def _stiffness(body, fixed_dofs) -> float:
    """N/m, the force over delta pressing the pad's front face (x = T) by delta = T / 1000
    towards its backing (x = 0), the dofs ``fixed_dofs`` (bool (3 m,)) held: x of the
    front face moved, the rest at rest; a static Newton solve."""
    delta = 1e-3 * T
    x0 = body.rest_positions
    energy = NeoHookeanTets(body.tetrahedra, x0, body.youngs_modulus, body.poisson_ratio)
    q = x0.copy()
    front = np.isclose(x0[:, 0], T)
    q[front, 0] -= delta
    q = q.ravel()
    free = ~fixed_dofs
    for _ in range(10):
        ev = energy.evaluate(q)
        hessian = sp.csc_matrix((ev.vals, (ev.rows, ev.cols)), shape=(q.size, q.size))
        step = spla.spsolve(hessian[free][:, free].tocsc(), -ev.gradient[free])
        q[free] += step
        if np.max(np.abs(step)) < 1e-15:
            break
    gradient = energy.evaluate(q, hessian=False).gradient.reshape(-1, 3)
    assert np.max(np.abs(gradient.ravel()[free])) < 1e-9
    # the plate holds the front nodes against their elastic force -gradient
    return -float(gradient[front, 0].sum()) / delta  # N/m: the stiffness


def test_the_pad_alone_has_the_closed_form_stiffness():
    body = _pad()
    x0 = body.rest_positions
    faces = np.isclose(x0[:, 0], T) | np.isclose(x0[:, 0], 0.0)
    area = H * W
    axial = np.zeros((body.n_nodes, 3), bool)
    axial[faces, 0] = True
    # frictionless plates: the rigid motions across them pinned at two backing corners
    corners = np.flatnonzero(faces & np.isclose(x0[:, 0], 0.0)
                             & np.isclose(np.abs(x0[:, 1]), W / 2)
                             & np.isclose(x0[:, 2], -H / 2))
    frictionless = axial.copy()
    frictionless[corners[0], 1:] = True
    frictionless[corners[1], 2] = True
    uniaxial_stress = _stiffness(body, frictionless.ravel())
    assert uniaxial_stress == pytest.approx(E * area / T, rel=5e-3)
    confined = axial.copy()
    confined[:, 1:] = True
    constrained_modulus = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    uniaxial_strain = _stiffness(body, confined.ravel())
    assert uniaxial_strain == pytest.approx(constrained_modulus * area / T, rel=5e-3)
    bonded = np.zeros((body.n_nodes, 3), bool)
    bonded[faces] = True
    on_the_jaw = _stiffness(body, bonded.ravel())
    assert 1.2 * uniaxial_stress < on_the_jaw < uniaxial_strain


@pytest.fixture(scope='module')
def default_apple_squeezes():
    return squeeze(PAD_3D), squeeze(['dimension=3'])


def test_the_pad_squeezes_the_default_apple_without_crossing(default_apple_squeezes):
    (sim, result, distances), _ = default_apple_squeezes
    assert_squeezed(sim, result, distances)
    # the fruit pushes the pads' front faces back (x < 0 in each finger's frame)
    fingers = result.fingers
    assert np.all(fingers.tip_displacement[:, 0] < 0)
    assert np.all(fingers.contact_area > 0)


def test_left_and_right_are_symmetric(default_apple_squeezes):
    (sim, result, _), _ = default_apple_squeezes
    left, right = result.deformation.jaw_contact_areas
    assert left == pytest.approx(right, rel=0.03)
    # the two fingers agree within one node's area (5 % more for its deformation)
    assert finger_area_difference(sim, result) <= 1.05
    assert -result.left_wrench.force[0] == pytest.approx(result.right_wrench.force[0],
                                                         rel=0.03)


def test_on_the_turgid_apple_the_contact_area_is_force_over_turgor(default_apple_squeezes):
    (_, pad, _), (_, flat, _) = default_apple_squeezes
    assert flat.grip_force == pytest.approx(pad.grip_force, rel=0.01)
    assert pad.deformation.contact_area == pytest.approx(flat.deformation.contact_area,
                                                         rel=0.03)


def test_on_the_solid_apple_the_pad_spreads_the_contact():
    """At 2 N the flat jaws' contact radii are Hertz's, a = (3 F R / (4 E*))^(1/3) (2.73
    mm; 2.57-2.67 mm), and the solid pads' contact is 1.19 times as large, its peak
    pressure lower. Before the 3D fruit started settled (2026-12-07) the flat jaws'
    radii were 1.79-1.97 mm, 30 % below Hertz's, and the pads' area 1.43 times theirs."""
    solid = ['fruit.model=solid', 'fruit.mesh.subdivisions=6', 'fruit.mesh.jaw_refinement=0.3']
    _, pad, distances = squeeze(PAD_3D + solid)
    sim, flat, _ = squeeze(['dimension=3'] + solid)
    c = sim.config
    modulus = c['fruit.flesh.youngs_modulus'] / (1 - c['fruit.flesh.poisson_ratio'] ** 2)
    hertz = (3 * 2.0 * 0.5 * c['fruit.shape.diameter'] / (4 * modulus)) ** (1 / 3)
    assert flat.deformation.jaw_contact_radii == pytest.approx((hertz, hertz), rel=0.1)
    assert min(distances) > 0.0
    assert pad.deformation.contact_area > 1.15 * flat.deformation.contact_area
    assert pad.deformation.peak_contact_pressure < flat.deformation.peak_contact_pressure


@pytest.mark.parametrize('finger', ['solid_pad', 'fin_ray'])
def test_the_markers_draw_the_3d_deformable_fingers(finger):
    config = load_config(overrides=['dimension=3', f'gripper.finger.type={finger}'])
    sim = Simulation3D(config)
    array = build_messages(sim.last, config, topics=['markers'])['markers']
    found = [m for m in array.markers if m.ns == 'soft_fingers']
    assert len(found) == 1
    points = np.array([(p.x, p.y, p.z) for p in found[0].points])
    fingers = sim.last.fingers
    assert points == pytest.approx(fingers.positions[fingers.surface_edges.ravel()])
    assert np.ptp(points[:, 1]) == pytest.approx(config['gripper.jaw_width'])


FIN_RAY = 'gripper.finger.fin_ray.'


@pytest.mark.parametrize('finger,overrides,match', [
    ('solid_pad', ['gripper.finger.solid_pad.thickness=0.04', 'gripper.max_gap=0.075'],
     "'gripper.finger.solid_pad.thickness'.*fill the jaw stroke"),
    ('solid_pad', ['gripper.jaw_width=0'], "'gripper.jaw_width'"),
    ('solid_pad', ['gripper.initial_gap=0.07'], "'gripper.initial_gap'.*does not fit"),
    ('solid_pad', ['gripper.finger.pad.enabled=true'], "'gripper.finger.pad.enabled'"),
    ('fin_ray', [FIN_RAY + 'rib_count=30', FIN_RAY + 'rib_thickness=0.0025'],
     f"'{FIN_RAY}rib_count'.*intersect"),
    ('fin_ray', [FIN_RAY + 'beam_thickness=0'], f"'{FIN_RAY}beam_thickness'"),
    ('fin_ray', [FIN_RAY + 'depth=0'], f"'{FIN_RAY}depth'"),
    ('fin_ray', ['gripper.max_gap=0.05'], f"'{FIN_RAY}base_width'.*fill the jaw stroke"),
    ('fin_ray', ['gripper.initial_gap=0.1'], "'gripper.initial_gap'.*does not fit"),
    ('fin_ray', ['gripper.finger.pad.enabled=true'], "'gripper.finger.pad.enabled'"),
    ('fin_ray', ['contact.restitution=0.3'], "'contact.restitution'"),
])
def test_bad_3d_deformable_fingers_are_one_line_errors_naming_the_key(finger, overrides, match):
    with pytest.raises(ConfigError, match=match) as info:
        Simulation3D(load_config(overrides=['dimension=3', f'gripper.finger.type={finger}']
                                 + overrides))
    assert '\n' not in str(info.value)
