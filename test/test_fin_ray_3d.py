"""The Fin Ray finger in 3D (``core3d.rod_extrusion``): the 2D finger's beams and ribs
extruded over its width into thin shells, on the jaws against the 3D fruit.

- The shells bend as plates: a strip clamped at one end under a tip line load deflects
  F L^3 / (3 D w) (Euler-Bernoulli with the plate stiffness D = E t^3 / (12 (1 - nu^2))
  per unit width: plane strain across the width), the same at every point across the
  width (no spurious twist).
- Per unit width, pressed uniformly across its width, the extruded finger is the 2D
  finger (``core.fin_ray``, plane stress: E t^3 / 12) with the plate modulus
  E / (1 - nu^2); the 2D finger of the bare modulus is that much softer in bending.
- The Fin Ray effect of the structure: pressed over the middle third, the tip moves
  towards the load.
- On the jaws (force mode): the grip met, no vertex of either body inside the other and
  no pair closer than 0 at any step, left and right alike; the contact area larger than
  the rigid flat finger's at equal force on the turgid shell apple (where a flat face
  gets F / turgor); on the solid apple at a firm grip the tip bends towards the fruit,
  the contact area is larger than the flat finger's and the peak pressure lower.
The markers and the bad configurations are test_soft_fingers_3d.py's, with the pad's.
"""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.fin_ray import fin_ray_body
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.finger_statics import static_equilibrium
from gripper_sim.core3d import meshes
from gripper_sim.core3d.rod_extrusion import extruded_rod_body, plate_stiffness
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.core3d.soft_fingers3d import fin_ray_body3d
from gripper_sim.geometry.fin_ray import FinRayGeometry
from gripper_sim.geometry.finger_materials import MATERIALS
from squeeze3d import assert_squeezed, squeeze

FIN_RAY_3D = ['dimension=3', 'gripper.finger.type=fin_ray']
#: the solid apple, meshed finer at the jaws
SOLID_APPLE = ['fruit.model=solid', 'fruit.mesh.subdivisions=5',
               'fruit.mesh.jaw_refinement=0.3']
#: a Fin Ray of 3 mm elements: at 8 N on that apple a quarter of the CPU time of the
#: default finger on a finer apple (subdivisions 6), the same figures within 5 %
COARSE_FIN_RAY = ('gripper.finger.fin_ray.element_length=0.003',)
TPU = MATERIALS['tpu']
WIDTH = 0.04


def _geometry() -> FinRayGeometry:
    return FinRayGeometry.from_config(load_config(overrides=FIN_RAY_3D), WIDTH)


def _line_load(section: FingerBody, body, forces2d: np.ndarray) -> np.ndarray:
    """(n, 3) N: the 2D loads ``forces2d`` (m2, 2) N, in (x, z), spread over the width
    of the extruded ``body``: each slice's copy of a node takes the share of the width
    it stands for."""
    copies = body.n_nodes // section.n_nodes
    share = np.full(copies, 1.0 / (copies - 1))
    share[[0, -1]] *= 0.5
    forces = np.zeros((copies, section.n_nodes, 3))
    forces[:, :, [0, 2]] = share[:, None, None] * forces2d[None]
    return forces.reshape(-1, 3)


def _static(body, forces: np.ndarray, increments: int = 8) -> np.ndarray:
    """(n, 3) m, the displacements of the 3D ``body`` under ``forces``, base held."""
    state = static_equilibrium(body, forces, increments=increments,
                               elastic=body.elastic_energies())
    return state.positions - body.rest_positions


def _front_press(section: FingerBody, force: float, spread: float):
    """((m2, 2) N, the front node at mid-height): ``force`` N along the front beam's inward
    normal on its nodes within ``spread`` m of mid-height (0: that node alone)."""
    x0 = section.rest_positions
    front = np.unique(section.surface_edges)
    mid = int(front[np.argmin(np.abs(x0[front, 1]))])
    ends = x0[section.surface_edges[[0, -1], [0, 1]]]
    along = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    inward = -np.array([along[1], -along[0]])
    loaded = front[np.abs(x0[front, 1]) <= spread] if spread > 0 else np.array([mid])
    forces = np.zeros_like(x0)
    forces[loaded] = force / len(loaded) * inward
    return forces, mid


# --- the body


def test_the_3d_fin_ray_is_its_members_extruded_into_shells():
    config = load_config(overrides=FIN_RAY_3D)
    body = fin_ray_body3d(config)
    section, g = body.section, _geometry()
    copies = body.n_nodes // section.n_nodes
    x = body.rest_positions
    assert body.n_nodes == copies * section.n_nodes and copies >= 3
    assert body.width == pytest.approx(config['gripper.jaw_width'])
    assert np.ptp(x[:, 1]) == pytest.approx(body.width)
    assert body.masses.sum() == pytest.approx(section.masses.sum() / section.depth * body.width)
    assert body.tetrahedra.size == 0
    # the base on the jaw, across the width; the beams and ribs their thicknesses
    assert np.all(x[body.base_nodes, 2] == pytest.approx(0.5 * g.length))
    assert body.base_nodes.size == copies * section.base_nodes.size
    assert set(np.round(body.shell_thickness * 1e4)) == {12.0, 8.0}
    # the contact surface is the front beam's strip, its area the beam's length times
    # the width
    front = np.unique(section.surface_edges)
    assert np.all(np.isin(body.surface_triangles % section.n_nodes, front))
    beam = np.linalg.norm(np.diff(section.rest_positions[section.surface_edges], axis=1),
                          axis=2).sum()
    area = meshes.vertex_areas(x, body.surface_triangles, body.n_nodes).sum()
    assert area == pytest.approx(beam * body.width)
    # at rest: no stress
    q = x.ravel()
    for energy in body.elastic_energies():
        assert energy.value(q) == pytest.approx(0.0, abs=1e-15)
        assert np.max(np.abs(energy.gradient(q))) < 1e-9
    # the width comes from gripper.finger.fin_ray.depth when set
    narrow = fin_ray_body3d(load_config(overrides=FIN_RAY_3D + [
        'gripper.finger.fin_ray.depth=0.02']))
    assert narrow.width == 0.02 and np.ptp(narrow.rest_positions[:, 1]) == pytest.approx(0.02)


def _strip(elements: int, length: float, thickness: float, width: float) -> FingerBody:
    """A straight beam along z clamped at its lower end (two base nodes, one element
    below the clamp), as the 2D rods model it."""
    h = length / elements
    z = np.arange(-1, elements + 1) * h
    n = len(z)
    lengths = np.full(n - 2, h)
    lengths[0] = 0.5 * h                       # the clamp stands for half the free edge
    return FingerBody(
        'fin_ray', np.column_stack([np.zeros(n), z]), np.full(n, 1e-4), np.array([0, 1]),
        np.stack([np.arange(1, n - 1), np.arange(2, n)], axis=1), n - 1, width,
        rod_edges=np.stack([np.arange(n - 1), np.arange(1, n)], axis=1),
        rod_axial_stiffness=np.full(n - 1, TPU.youngs_modulus * thickness * width),
        bend_triples=np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], 1),
        bend_stiffness=np.full(n - 2, TPU.youngs_modulus * thickness ** 3 * width / 12),
        bend_lengths=lengths, youngs_modulus=TPU.youngs_modulus,
        poisson_ratio=TPU.poisson_ratio)


@pytest.mark.parametrize('elements,slices,tolerance', [(5, 2, 0.025), (25, 6, 0.002)])
def test_a_clamped_strip_bends_as_an_euler_bernoulli_plate(elements, slices, tolerance):
    """A 50 mm strip, 1.2 mm thick, 20 mm wide, 1 mN at its tip across the width (small
    deflection): F L^3 / (3 D w) within 2.5 % with 5 elements along it (the 2D rods' own
    discretisation error) and 0.2 % with 25, the same all across the width."""
    length, t, w, force = 0.05, 0.0012, 0.02, 1e-3
    section = _strip(elements, length, t, w)
    body = extruded_rod_body(section, w, slices)
    loads = np.zeros((section.n_nodes, 2))
    loads[section.tip_node, 0] = force
    moved = _static(body, _line_load(section, body, loads), increments=1)
    tips = section.tip_node + section.n_nodes * np.arange(slices + 1)
    plate = force * length ** 3 / (3 * plate_stiffness(TPU.youngs_modulus,
                                                       TPU.poisson_ratio, t) * w)
    assert moved[tips, 0] == pytest.approx(plate, rel=tolerance)
    assert np.ptp(moved[tips, 0]) < 1e-6 * plate


def test_per_unit_width_the_3d_finger_is_the_2d_finger_with_the_plate_modulus():
    """The default finger 40 mm wide pressed at mid-height across its width by 0.05 and
    2 N: the pressed line's displacement within 1 % of the 2D finger's (as deep, bending
    as a plate: modulus E / (1 - nu^2)), the tip's within 2 % of it; the 2D finger of modulus E (plane
    stress) is 1 / (1 - nu^2) softer."""
    g = _geometry()
    section = fin_ray_body(g, TPU)
    body = extruded_rod_body(section, WIDTH, 4)
    planar = fin_ray_body(g, TPU, 'plate')    # gripper.finger.fin_ray.section: plate
    middle = 2 * section.n_nodes
    for force in (0.05, 2.0):
        loads, mid = _front_press(section, force, spread=0.0)
        moved = _static(body, _line_load(section, body, loads))[middle:middle + section.n_nodes]
        reference = static_equilibrium(planar, loads).positions - planar.rest_positions
        scale = np.linalg.norm(reference[mid])
        assert np.linalg.norm(moved[mid][[0, 2]] - reference[mid]) < 0.01 * scale
        tip = section.tip_node
        assert np.linalg.norm(moved[tip][[0, 2]] - reference[tip]) < 0.02 * scale
    stress = static_equilibrium(section, loads).positions - section.rest_positions
    assert moved[mid, 0] / stress[mid, 0] == pytest.approx(1 - TPU.poisson_ratio ** 2,
                                                           rel=0.02)


def test_pressed_over_its_middle_third_the_3d_tip_bends_towards_the_load():
    """The Fin Ray effect of the structure: 12 N over the middle third of the front beam
    of the 40 mm wide finger (the 2D test's 6 N on 20 mm) moves the tip towards the
    load (+x) by a few tenths of a millimetre while the front beam goes in by
    millimetres; symmetric across the width, the free edges' tips ahead of the middle's
    by a few percent (the membrane's Poisson contraction, free at the edges)."""
    g = _geometry()
    section = fin_ray_body(g, TPU)
    body = extruded_rod_body(section, WIDTH, 4)
    loads, mid = _front_press(section, 12.0, spread=g.length / 6)
    moved = _static(body, _line_load(section, body, loads))
    lines = np.arange(5) * section.n_nodes
    assert np.all(moved[mid + lines, 0] < -0.003)
    assert np.all(moved[section.tip_node + lines, 0] > 0.2e-3)
    tips = moved[section.tip_node + lines, 0]
    assert tips[0] == pytest.approx(tips[-1], rel=1e-3)
    assert np.ptp(tips) < 0.1 * tips.min()


# --- on the jaws


def test_the_contact_pattern_is_the_grasps_wherever_the_jaws_start():
    """The barrier's pattern pairs (fruit node, finger node) are those of the fruit
    centred on the jaws in height, where they grasp it: a pick that starts the jaws 2 cm
    above (``approach.height``) gets the same pairs (pairs from the start would miss the
    grasp, and its first touch would not converge)."""
    centred = Simulation3D(load_config(overrides=FIN_RAY_3D))
    above = Simulation3D(load_config(overrides=FIN_RAY_3D + [
        f'gripper.initial_lift={centred.initial_lift + 0.02}']))
    assert above.initial_lift == pytest.approx(centred.initial_lift + 0.02)
    assert np.array_equal(above._barrier.pattern_pairs, centred._barrier.pattern_pairs)


def _squeezes(*overrides: str, force: float = 2.0, max_steps: int = 80,
              fin_ray: tuple = ()) -> dict:
    """{finger: (simulation, result, distances)} of squeezes to ``force`` N with the Fin
    Ray (with the overrides ``fin_ray`` too) and the rigid flat finger
    (``squeeze3d.squeeze``)."""
    own = {'fin_ray': list(fin_ray), 'flat': []}
    return {finger: squeeze(['dimension=3', f'gripper.finger.type={finger}', *overrides,
                             *own[finger]], force=force, max_steps=max_steps)
            for finger in own}


def _compared(case: str, squeezes: dict, capsys) -> tuple:
    """(Fin Ray's result, flat finger's) of ``squeezes`` (``_squeezes``), at equal force;
    prints their contact areas, peak pressures and the Fin Ray's tip displacement."""
    fin_ray, flat = squeezes['fin_ray'][1], squeezes['flat'][1]
    assert flat.grip_force == pytest.approx(fin_ray.grip_force, rel=0.02)
    with capsys.disabled():
        print(f'\n  {case}: contact area Fin Ray '
              f'{fin_ray.deformation.contact_area * 1e6:.0f} mm^2, flat '
              f'{flat.deformation.contact_area * 1e6:.0f} mm^2; peak pressure '
              f'{fin_ray.deformation.peak_contact_pressure / 1e3:.1f} against '
              f'{flat.deformation.peak_contact_pressure / 1e3:.1f} kPa; Fin Ray tip '
              f'{fin_ray.fingers.tip_displacement[0, 0] * 1e3:+.3f} mm')
    return fin_ray, flat


@pytest.fixture(scope='module')
def default_apple_squeezes():
    return _squeezes()


def test_the_fin_ray_squeezes_the_default_apple_without_crossing(default_apple_squeezes):
    sim, result, distances = default_apple_squeezes['fin_ray']
    assert_squeezed(sim, result, distances)
    fingers = result.fingers
    # the front beam touches over an area on each finger. Left and right alike in force
    # (above) and tips (below); their areas (nodes in a pair closer than dhat) less so:
    # the front beam lies along the wrapped skin over a wide rim at nearly no pressure,
    # whose nodes go in or out of dhat as the fruit drifts sideways by micrometres (the
    # mirror-symmetric squeeze is so only up to round-off: 142 and 149 mm^2 with the 1 um gap)
    assert np.all(fingers.contact_area > 0)
    assert fingers.contact_area[0] == pytest.approx(fingers.contact_area[1], rel=0.25)
    # the tips move by tens of micrometres (the front beam is pressed in by a millimetre)
    assert fingers.tip_displacement[0] == pytest.approx(fingers.tip_displacement[1],
                                                        abs=5e-6)
    # the fruit's patches likewise (252 and 212 mm^2: their nodes within the Fin Ray's
    # contact gap, 0.1 mm, take in more of that rim than the 1 um of contact.ipc.dhat did,
    # 158 and 143 mm^2)
    left, right = result.deformation.jaw_contact_areas
    assert left == pytest.approx(right, rel=0.25)
    assert result.damage is not None


def test_the_same_squeeze_twice_ends_in_the_same_state(default_apple_squeezes):
    """Bit for bit: the barrier's pairs come in the same order every run (ipctk in one
    thread, ``core.barrier``), so the squeeze takes the same steps to the same state."""
    _, first, _ = default_apple_squeezes['fin_ray']
    _, again, _ = squeeze(FIN_RAY_3D)
    assert again.step == first.step
    assert np.array_equal(again.positions, first.positions)
    assert np.array_equal(again.fingers.positions, first.fingers.positions)


def test_on_the_turgid_apple_the_wrap_spreads_the_contact(default_apple_squeezes, capsys):
    """The front beam wraps the fruit: its skin stays curved where it touches, so its
    tension carries part of the turgor and the contact pressure falls below it; the
    contact grows beyond the flat finger's F / turgor."""
    fin_ray, flat = _compared('default apple at 2 N', default_apple_squeezes, capsys)
    assert fin_ray.deformation.contact_area > 1.5 * flat.deformation.contact_area


@pytest.fixture(scope='module')
def solid_apple_squeezes():
    return _squeezes(*SOLID_APPLE, force=8.0, max_steps=120, fin_ray=COARSE_FIN_RAY)


def test_a_firm_grip_bends_the_tip_towards_the_fruit(solid_apple_squeezes):
    _, result, distances = solid_apple_squeezes['fin_ray']
    assert result.grip_force == pytest.approx(8.0, rel=0.01)
    assert min(distances) > 0.0
    assert np.all(result.fingers.tip_displacement[:, 0] > 0)


def test_the_fin_ray_spreads_the_contact_and_lowers_the_peak_pressure(solid_apple_squeezes,
                                                                       capsys):
    fin_ray, flat = _compared('solid apple at 8 N', solid_apple_squeezes, capsys)
    assert fin_ray.deformation.contact_area > 1.2 * flat.deformation.contact_area
    assert (fin_ray.deformation.peak_contact_pressure
            < 0.9 * flat.deformation.peak_contact_pressure)

