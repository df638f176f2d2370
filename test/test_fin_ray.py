"""The Fin Ray finger as a structure, on its own (base held, loads on the front beam):
its configuration and checks, its rods, the linear frame it must reproduce, and the Fin
Ray effect.

No published Fin Ray study in the sources available here gives a geometry, a material
and force-displacement figures complete enough to reproduce, so the model is checked
against closed forms instead: a linear Euler-Bernoulli frame solved by the direct
stiffness method (``frame_reference``; the rib-free finger is its limit with the ribs
taken out) and, in test_energies_rods.py, the cantilever P L^3 / (3 EI).
"""
import dataclasses

import numpy as np
import pytest

from frame_reference import frame_displacements
from gripper_sim.configuration import load_config
from gripper_sim.core.fin_ray import fin_ray_body, fin_ray_from_config
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.finger_statics import static_equilibrium
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConfigError
from gripper_sim.geometry.fin_ray import MAX_SECTION_NODES, FinRayGeometry, layout
from gripper_sim.geometry.finger_materials import MATERIALS

FIN_RAY = 'gripper.finger.type=fin_ray'


def _config(*overrides):
    return load_config(overrides=[FIN_RAY, *overrides])


#: the rod element length the finger's structure is checked at (the default follows the
#: fruit: 4 mm on the default apple, ``test_small_loads_give_the_linear_frame_displacements``)
STRUCTURE_ELEMENT = 'gripper.finger.fin_ray.element_length=0.002'


def _geometry(**changes) -> FinRayGeometry:
    """The default Fin Ray with 2 mm elements, 20 mm deep, with ``changes``."""
    return dataclasses.replace(FinRayGeometry.from_config(_config(STRUCTURE_ELEMENT), 0.02),
                               **changes)


def _front_normal(body: FingerBody) -> np.ndarray:
    """(2,) the front beam's unit normal towards the fruit."""
    front = body.rest_positions[body.surface_edges[[0, -1], [0, 1]]]
    t = (front[1] - front[0]) / np.linalg.norm(front[1] - front[0])
    return np.array([t[1], -t[0]])


def _press(body: FingerBody, force: float, spread: float) -> tuple[np.ndarray, int]:
    """((n, 2) N, the loaded node at mid-height): ``force`` N pressing the front beam
    along its inward normal, on the nodes within ``spread`` m of mid-height (0: the
    node nearest it), as a fruit or a cylinder would."""
    x0 = body.rest_positions
    front = np.unique(body.surface_edges)
    mid = int(front[np.argmin(np.abs(x0[front, 1]))])
    loaded = front[np.abs(x0[front, 1]) <= spread] if spread > 0 else np.array([mid])
    forces = np.zeros_like(x0)
    forces[loaded] = -force / len(loaded) * _front_normal(body)
    return forces, mid


# --- configuration


@pytest.mark.parametrize('override,key,words', [
    ('gripper.finger.fin_ray.rib_count=0', 'rib_count', 'out of range'),
    ('gripper.finger.fin_ray.beam_thickness=0', 'beam_thickness', 'out of range'),
    ('gripper.finger.fin_ray.rib_thickness=-0.001', 'rib_thickness', 'out of range'),
    ('gripper.finger.fin_ray.rib_count=30 gripper.finger.fin_ray.rib_thickness=0.0025',
     'rib_count', 'the ribs intersect'),
    ('gripper.finger.fin_ray.rib_angle=-50', 'rib_angle', 'leaves the finger'),
    # the default angle (null: perpendicular to the back beam) on a wider base: the
    # message says the angle was derived and which keys to change
    ('gripper.finger.fin_ray.base_width=0.04', 'rib_angle',
     'rib_angle is null, so perpendicular to the back beam: set it (a larger angle)'),
    # the derived angle (perpendicular to the back beam) parallel to the front beam: a
    # singular system and a traceback before 2026-12-03
    ('gripper.finger.fin_ray.length=0.01', 'rib_angle',
     'the ribs run parallel to the front beam: they never meet it; rib_angle is null'),
    ('gripper.finger.fin_ray.beam_thickness=0.013', 'beam_thickness', 'fill the base'),
    ('gripper.finger.fin_ray.tip_offset=0.03', 'tip_offset', 'between the backing'),
    ('gripper.finger.fin_ray.material=custom', 'youngs_modulus', 'must be set'),
    ('gripper.finger.fin_ray.material=wood', 'material', 'must be one of'),
    # inside the key's range (> 0), but 200,000 nodes: their contact pairs' matrices
    # took 612 GiB
    ('gripper.finger.fin_ray.element_length=1e-6', 'element_length',
     'too fine: the members (203 mm in all) would have about 2.03e+05 nodes, at most 1000: '
     'use 0.00021 m or more'),
])
def test_a_bad_fin_ray_is_a_one_line_error_naming_the_key(override, key, words):
    with pytest.raises(ConfigError, match=f"'gripper.finger.fin_ray.{key}'") as info:
        _config(*override.split())
    assert words in str(info.value) and '\n' not in str(info.value)


def test_the_finest_fin_ray_the_error_suggests_is_built():
    config = _config('gripper.finger.fin_ray.element_length=0.00021')
    assert Simulation(config)._soft.body.n_nodes <= MAX_SECTION_NODES


def test_fin_ray_keys_without_a_fin_ray_have_no_effect():
    with pytest.warns(UserWarning, match="'gripper.finger.fin_ray.rib_count' has no effect: "
                                         'the finger is flat, not a Fin Ray'):
        load_config(overrides=['gripper.finger.fin_ray.rib_count=6'])


@pytest.mark.parametrize('overrides,words', [
    (['gripper.finger.fin_ray.poisson_ratio=0.3'], "the Fin Ray's material is tpu"),
    (['dimension=3', 'gripper.finger.fin_ray.section=plate'],
     "in 3D the Fin Ray's members are shells"),
])
def test_section_and_poisson_keys_say_where_they_have_no_effect(overrides, words):
    with pytest.warns(UserWarning, match=words):
        load_config(overrides=['gripper.finger.type=fin_ray'] + overrides)


@pytest.mark.parametrize('override,words', [
    ('section=shell', 'must be one of beam, plate'),
    ('poisson_ratio=0.5', 'out of range'),
    ('poisson_ratio=-0.1', 'out of range'),
])
def test_bad_section_or_poisson_ratio_is_refused(override, words):
    with pytest.raises(ConfigError, match=words):
        load_config(overrides=['gripper.finger.type=fin_ray',
                               'gripper.finger.fin_ray.material=custom',
                               'gripper.finger.fin_ray.youngs_modulus=1e8',
                               f'gripper.finger.fin_ray.{override}'])


def test_fin_ray_body_refuses_an_unknown_section():
    with pytest.raises(ValueError, match="section 'shell': must be one of beam, plate"):
        fin_ray_body(_geometry(), MATERIALS['tpu'], 'shell')


@pytest.mark.parametrize('override,key,words', [
    ('gripper.max_gap=0.05', 'gripper.finger.fin_ray.base_width', 'fill the jaw stroke'),
    ('gripper.max_gap=0.09', 'gripper.max_gap', 'does not fit between the fin_ray fingers'),
    ('gripper.initial_gap=0.09', 'gripper.initial_gap', 'does not fit'),
])
def test_fingers_that_leave_no_room_for_the_fruit_are_refused(override, key, words):
    with pytest.raises(ConfigError, match=f"config key '{key}'.*{words}"):
        Simulation(_config(override))


def test_the_simulation_puts_a_fin_ray_on_each_jaw():
    sim = Simulation(_config())
    # the front beam x = 22.5 mm + z / 12 meets the 31.75 mm circle at z = 2.6 mm
    assert sim.touching_gap == pytest.approx(0.10871, abs=1e-4)
    assert sim.initial_gap == pytest.approx(sim.touching_gap + 0.01)
    finger = fin_ray_from_config(_config(), sim.fruit.depth)
    result = sim.step()
    assert result.fingers.positions.shape == (2 * finger.n_nodes, 2)
    assert np.allclose(result.fingers.tip_displacement, 0.0, atol=1e-4)


# --- the rods


def test_members_carry_ea_and_ei_of_their_sections():
    config = _config(STRUCTURE_ELEMENT, 'gripper.finger.fin_ray.material=custom',
                     'gripper.finger.fin_ray.youngs_modulus=5e7',
                     'gripper.finger.fin_ray.density=1000')
    body = fin_ray_from_config(config, 0.042)
    g = FinRayGeometry.from_config(config, 0.042)
    assert g.depth == 0.042
    plan = layout(g)
    x0 = body.rest_positions
    edge_index = {tuple(sorted(e)): i for i, e in enumerate(body.rod_edges.tolist())}
    total_mass = 0.0
    for member in plan.members:
        for a, b in zip(member.nodes[:-1], member.nodes[1:]):
            i = edge_index[tuple(sorted((int(a), int(b))))]
            assert body.rod_axial_stiffness[i] == pytest.approx(5e7 * member.thickness * g.depth)
            total_mass += 1000 * member.thickness * g.depth * np.hypot(*(x0[b] - x0[a]))
    assert body.masses.sum() == pytest.approx(total_mass)
    beam_ei = 5e7 * g.beam_thickness ** 3 * g.depth / 12
    rib_ei = 5e7 * g.rib_thickness ** 3 * g.depth / 12
    interior = body.bend_stiffness[np.isclose(body.bend_stiffness, beam_ei)]
    assert len(interior) > 40 and np.any(np.isclose(body.bend_stiffness, rib_ei))
    assert len(body.rod_edges) == sum(len(m.nodes) - 1 for m in plan.members)


def test_plate_members_carry_ea_and_ei_over_one_minus_nu_squared():
    """``section: plate``: plane strain across the depth, every member's EA and EI (the
    joints' too) divided by 1 - nu^2 of the custom material's nu; nothing else changes."""
    keys = ('gripper.finger.fin_ray.material=custom',
            'gripper.finger.fin_ray.youngs_modulus=5e7', 'gripper.finger.fin_ray.density=1000',
            'gripper.finger.fin_ray.poisson_ratio=0.3')
    beam = fin_ray_from_config(_config(*keys), 0.042)
    plate = fin_ray_from_config(_config(*keys, 'gripper.finger.fin_ray.section=plate'), 0.042)
    factor = 1.0 / (1.0 - 0.3 ** 2)
    assert np.allclose(plate.rod_axial_stiffness, factor * beam.rod_axial_stiffness,
                       rtol=1e-14)
    assert np.allclose(plate.bend_stiffness, factor * beam.bend_stiffness, rtol=1e-14)
    assert np.array_equal(plate.masses, beam.masses)
    assert np.array_equal(plate.bend_triples, beam.bend_triples)
    assert plate.poisson_ratio == beam.poisson_ratio == 0.3


def test_the_finger_stands_on_its_base_and_faces_the_fruit():
    g = _geometry()
    body = fin_ray_body(g, MATERIALS['tpu'])
    x0 = body.rest_positions
    assert np.allclose(x0[body.base_nodes, 1], 0.5 * g.length)
    assert np.ptp(x0[body.base_nodes, 0]) == pytest.approx(g.base_width)
    assert np.allclose(x0[body.tip_node], [g.tip_offset, -0.5 * g.length])
    assert _front_normal(body)[0] > 0.9
    lengths = np.linalg.norm(x0[body.rod_edges[:, 1]] - x0[body.rod_edges[:, 0]], axis=1)
    assert lengths.max() <= g.element_length * (1 + 1e-9)
    edges = x0[body.surface_edges[:, 1]] - x0[body.surface_edges[:, 0]]
    assert np.all(edges[:, 1] > 0), 'the surface runs from the tip up to the base'
    assert np.all(body.surface_edges[1:, 0] == body.surface_edges[:-1, 1])


def test_the_rest_shape_is_in_equilibrium():
    body = fin_ray_body(_geometry(rib_angle=-20.0, tip_offset=0.008), MATERIALS['tpu'])
    q = body.rest_positions.ravel()
    for energy in body.rod_energies():
        assert energy.value(q) == pytest.approx(0.0, abs=1e-15)
        assert np.max(np.abs(energy.gradient(q))) < 1e-9


# --- the structure


@pytest.mark.parametrize('rib_count, element, within', [
    (0, 0.002, 0.02), (4, 0.002, 0.02), (6, 0.002, 0.02), (0, 0.004, 0.04),
    (4, 0.004, 0.04), (6, 0.004, 0.04)])
def test_small_loads_give_the_linear_frame_displacements(rib_count, element, within):
    """A 10 mN press at mid-height: the rod model's displacements (the loaded node and the
    tip) are those of the linear Euler-Bernoulli frame of the same members with rigid
    joints, within 2 % of the loaded node's displacement with 2 mm elements, 4 % with the
    default apple's 4 mm (2.0-3.5 %: the rods bend at their nodes)."""
    g = _geometry(rib_count=rib_count, element_length=element)
    material = MATERIALS['tpu']
    body = fin_ray_body(g, material)
    plan = layout(g)
    forces, mid = _press(body, 0.01, spread=0.0)
    moved = static_equilibrium(body, forces, increments=1).positions - body.rest_positions
    e, b = material.youngs_modulus, g.depth
    frame = frame_displacements(body.rest_positions, [m.nodes for m in plan.members],
                                [e * m.thickness * b for m in plan.members],
                                [e * m.thickness ** 3 * b / 12 for m in plan.members],
                                plan.base_nodes, forces)
    scale = np.linalg.norm(frame[mid])
    assert scale > 1e-6
    assert np.linalg.norm(moved[mid] - frame[mid]) < within * scale
    assert np.linalg.norm(moved[body.tip_node] - frame[body.tip_node]) < within * scale


def test_ribs_stiffen_the_finger_and_the_load_grows_with_the_press():
    """Force against displacement of the front beam at mid-height: monotonic, and ribs
    make the finger stiffer than the rib-free frame."""
    body = fin_ray_body(_geometry(), MATERIALS['tpu'])
    travel = []
    for force in (1.0, 2.0, 4.0, 8.0):
        forces, mid = _press(body, force, spread=0.01)
        moved = static_equilibrium(body, forces).positions - body.rest_positions
        travel.append(-moved[mid] @ _front_normal(body))
    assert np.all(np.diff(travel) > 0)
    rib_free = fin_ray_body(_geometry(rib_count=0), MATERIALS['tpu'])
    forces, mid = _press(rib_free, 1.0, spread=0.01)
    moved = static_equilibrium(rib_free, forces).positions - rib_free.rest_positions
    assert -moved[mid] @ _front_normal(rib_free) > 2 * travel[0]


def _front_cantilever(g: FinRayGeometry) -> FingerBody:
    """The front beam alone, clamped at the base: a plain inclined cantilever."""
    body = fin_ray_body(g, MATERIALS['tpu'])
    plan = layout(g)
    front = next(m for m in plan.members if m.name == 'front').nodes
    keep = np.concatenate([front, plan.base_nodes])
    index = -np.ones(body.n_nodes, np.int64)
    index[keep] = np.arange(len(keep))
    rods = np.all(index[body.rod_edges] >= 0, axis=1)
    bends = np.all(index[body.bend_triples] >= 0, axis=1)
    return dataclasses.replace(
        body, rest_positions=body.rest_positions[keep], masses=body.masses[keep],
        base_nodes=index[plan.base_nodes], surface_edges=index[body.surface_edges],
        tip_node=int(index[body.tip_node]), rod_edges=index[body.rod_edges[rods]],
        rod_axial_stiffness=body.rod_axial_stiffness[rods],
        bend_triples=index[body.bend_triples[bends]],
        bend_stiffness=body.bend_stiffness[bends], bend_lengths=body.bend_lengths[bends])


@pytest.mark.parametrize('spread', [0.0, 0.01])
def test_pressed_at_mid_height_the_tip_bends_towards_the_load(spread):
    """The Fin Ray effect: 6 N pressing the front beam at mid-height (at a point, or over
    its middle third as a fruit would) moves the tip towards the fruit (+x) by more than
    half a millimetre, while the front beam alone, a plain cantilever (pressed far less,
it is far softer), swings its tip away, further than the pressed point."""
    g = _geometry()
    finger = fin_ray_body(g, MATERIALS['tpu'])
    forces, mid = _press(finger, 6.0, spread)
    moved = static_equilibrium(finger, forces).positions - finger.rest_positions
    assert moved[mid, 0] < -0.004, 'the front beam is pressed in by millimetres'
    assert moved[finger.tip_node, 0] > 0.5e-3
    cantilever = _front_cantilever(g)
    forces, mid = _press(cantilever, 0.05, spread)
    swung = static_equilibrium(cantilever, forces).positions - cantilever.rest_positions
    assert swung[mid, 0] < -1e-3
    assert swung[cantilever.tip_node, 0] < 2 * swung[mid, 0]


def test_a_null_depth_is_the_fruits_and_a_set_one_is_kept():
    assert FinRayGeometry.from_config(_config(), 0.042).depth == 0.042
    config = _config('gripper.finger.fin_ray.depth=0.03')
    assert FinRayGeometry.from_config(config, 0.042).depth == 0.03
    assert fin_ray_from_config(config, 0.042).depth == 0.03
