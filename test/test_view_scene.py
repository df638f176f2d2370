"""The live view's 3D scene: the node's markers as a Foxglove SceneUpdate (no server)."""
from __future__ import annotations

import copy
import math
import subprocess
import sys

import numpy as np
import pytest
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from gripper_sim.configuration import load_config
from gripper_sim.convert import messages
from gripper_sim.convert.finger_markers import base_marker
from gripper_sim.view.scene import (ARROW_CAP, CHARACTER_WIDTH, LEGEND_STEPS,
                                    PressureLegend, jaw_arrow_length, legend_entity,
                                    rotation_from_x, scene_of_batch, scene_update)
from gripper_sim.workflows.factory import make_simulation
from view_client import decode_foxglove


def rotate(q, v):
    """Vector ``v`` rotated by the unit quaternion ``q`` (dict x, y, z, w)."""
    u = np.array([q['x'], q['y'], q['z']], dtype=float)
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + q['w'] * v)


def xyz(point):
    return (point['x'], point['y'], point['z'])


def rg(colour):
    return (colour['r'], colour['g'])


def squeeze(fruit=None, finger=None):
    """A 2D grasp a few steps in (the jaws pressing), its context and message batch."""
    config = load_config(fruit=fruit, finger=finger, overrides=['fruit.nodes=32'])
    sim = make_simulation(config)
    context = messages.MessageContext.from_config(config, initial=sim.last)
    sim.command_force(5.0)
    result = sim.last
    for _ in range(5000):
        result = sim.step()
        context.observe(result)
        if result.grip_force > 1.0:
            break
    assert result.grip_force > 1.0, 'the jaws never pressed the fruit'
    return context, messages.build_messages(result, context)


@pytest.fixture(scope='module')
def squeezed():
    return squeeze()


def test_every_marker_becomes_an_entity_with_its_points_and_colours(squeezed):
    context, batch = squeezed
    legend = PressureLegend.beside(context)
    update = decode_foxglove(scene_of_batch(batch, legend, 123))
    entities = {e['id']: e for e in update['entities']}
    added = [m for m in batch['markers'].markers if m.action == Marker.ADD]
    deleted = [m for m in batch['markers'].markers if m.action == Marker.DELETE]
    assert {f'{m.ns}/{m.id}' for m in added} | {'legend/pressure', 'legend/state'} \
        == set(entities)
    assert {d['id'] for d in update['deletions']} == {f'{m.ns}/{m.id}' for m in deleted}

    outline = next(m for m in added if m.ns == 'fruit_outline')
    line = entities['fruit_outline/0']['lines'][0]
    assert len(line['points']) == len(outline.points) > 10
    assert [xyz(p) for p in line['points']] == [(p.x, p.y, p.z) for p in outline.points]
    assert [rg(c) for c in line['colors']] == [(c.r, c.g) for c in outline.colors]
    # pressed against the jaws: the outline is not one colour
    assert len({rg(c) for c in line['colors']}) > 1
    assert line['thickness'] == outline.scale.x
    table = next(m for m in added if m.ns == 'table')
    cube = entities['table/0']['cubes'][0]
    assert (cube['size']['x'], cube['size']['z']) == (table.scale.x, table.scale.z)
    assert cube['pose']['position']['z'] == table.pose.position.z
    assert all(e['frame_id'] == 'world' for e in entities.values())
    state = batch['fruit/state']
    text = entities['legend/state']['texts'][0]['text']
    assert f'grip {state.grip_force:.2f} N' in text
    assert f'compression {1e3 * state.compression:.2f} mm' in text


def test_an_arrow_runs_from_its_first_to_its_second_point():
    """(But a jaw force arrow: ``test_jaw_force_arrows_stay_clear_...``.)"""
    header = Header(frame_id='world')
    marker = base_marker(header, 'arrows', 0, Marker.ARROW)
    marker.points = [Point(x=0.01, y=0.0, z=0.02), Point(x=0.01, y=0.0, z=0.12)]
    marker.scale.x, marker.scale.y, marker.scale.z = 0.002, 0.004, 0.02
    marker.color = ColorRGBA(r=1.0, a=1.0)
    arrow = decode_foxglove(scene_update([marker]))['entities'][0]['arrows'][0]
    assert arrow['shaft_length'] == pytest.approx(0.08)
    assert arrow['head_length'] == pytest.approx(0.02)
    assert (arrow['shaft_diameter'], arrow['head_diameter']) == (0.002, 0.004)
    assert xyz(arrow['pose']['position']) == (0.01, 0, 0.02)
    assert rotate(arrow['pose']['orientation'], [1, 0, 0]) == \
        pytest.approx([0, 0, 1], abs=1e-12)


@pytest.mark.parametrize('direction', [(1, 0, 0), (-1, 0, 0), (0.3, -2.0, 0.5), (0, 0, -4)])
def test_rotation_from_x_takes_x_onto_the_direction(direction):
    unit = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    q = decode_foxglove(rotation_from_x(direction))
    assert math.isclose(sum(q[k] ** 2 for k in 'xyzw'), 1.0)
    assert rotate(q, [1, 0, 0]) == pytest.approx(unit, abs=1e-12)


def test_a_3d_skin_becomes_a_triangle_list_with_a_colour_per_corner():
    header = Header(frame_id='world')
    marker = base_marker(header, 'fruit_mesh', 0, Marker.TRIANGLE_LIST)
    corners = [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (0, 0, 0.01), (0.01, 0, 0), (0, 0.01, 0)]
    marker.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in corners]
    marker.colors = [messages.pressure_colour(p, 100e3) for p in (0, 0, 0, 50e3, 100e3, 0)]
    triangles = decode_foxglove(scene_update([marker]))['entities'][0]['triangles'][0]
    assert [xyz(p) for p in triangles['points']] == corners
    assert [rg(c) for c in triangles['colors']] == [(c.r, c.g) for c in marker.colors]


def test_deleting_markers_delete_their_entities():
    header = Header(frame_id='world')
    gone = base_marker(header, 'contact_forces', 0, Marker.LINE_LIST)
    gone.action = Marker.DELETE
    everything = base_marker(header, '', 0, Marker.ARROW)
    everything.action = Marker.DELETEALL
    update = decode_foxglove(scene_update([gone, everything], stamp_ns=7))
    assert update['entities'] == []
    # SceneEntityDeletion.Type: MATCHING_ID 0, ALL 1
    assert [(d['id'], d['type']) for d in update['deletions']] == \
        [('contact_forces/0', 0), ('', 1)]


def test_the_legend_states_its_scale_and_shows_its_colours():
    legend = PressureLegend(bruise_pressure=200e3, x=-0.1, y=0.0, z=0.0, height=0.06)
    entity = decode_foxglove(legend_entity(legend, 5))
    assert len(entity['cubes']) == LEGEND_STEPS
    for k, cube in enumerate(entity['cubes']):
        expected = messages.pressure_colour((k + 0.5) / LEGEND_STEPS * 200e3, 200e3)
        assert (cube['color']['r'], cube['color']['g'], cube['color']['b']) == \
            pytest.approx((expected.r, expected.g, expected.b))
    bottom, top = entity['cubes'][0], entity['cubes'][-1]
    assert rg(bottom['color']) != rg(top['color'])
    assert top['pose']['position']['z'] > bottom['pose']['position']['z']
    labels = [t['text'] for t in entity['texts']]
    assert labels[:3] == ['0 kPa', '100 kPa', '>= 200 kPa (bruise)']
    assert 'contact pressure' in labels[3]


def test_the_scene_module_leaves_rclpy_out():
    code = ('import sys, gripper_sim.view.scene; '
            "sys.exit(1 if 'rclpy' in sys.modules else 0)")
    assert subprocess.run([sys.executable, '-c', code]).returncode == 0


def test_a_3d_fruit_is_drawn_as_its_skin_coloured_by_pressure():
    config = load_config(overrides=['dimension=3', 'fruit.mesh.subdivisions=3',
                                    'sim.dt=0.002'])
    sim = make_simulation(config)
    context = messages.MessageContext.from_config(config, initial=sim.last)
    batch = messages.build_messages(sim.step(), context)
    update = decode_foxglove(scene_of_batch(batch, PressureLegend.beside(context), 0))
    skin = next(e for e in update['entities'] if e['id'] == 'fruit_mesh/0')
    triangles = skin['triangles'][0]
    mesh = next(m for m in batch['markers'].markers if m.ns == 'fruit_mesh')
    assert len(triangles['points']) == len(mesh.points) == 3 * len(sim.last.triangles)
    assert len(triangles['colors']) == len(triangles['points'])
    assert [xyz(p) for p in triangles['points'][:6]] == \
        [(p.x, p.y, p.z) for p in mesh.points[:6]]


# ---------------------------------------------------------------- jaw force arrows
#: N: a light grip, the pick's (config/scenarios) and GripperCommand's default
#: (max_effort), gripper.max_force's default and the largest it may be set to
FORCES = (0.5, 5.0, 10.0, 200.0, 1e5)


def text_box(text):
    """(x min, x max, z min, z max) of a label as Foxglove draws it: centred on its
    pose, a line height per line, characters CHARACTER_WIDTH line heights wide."""
    size = text['font_size']
    lines = text['text'].split('\n')
    half_width = 0.5 * CHARACTER_WIDTH * size * max(len(line) for line in lines)
    half_height = 0.5 * size * len(lines)
    x, z = text['pose']['position']['x'], text['pose']['position']['z']
    return x - half_width, x + half_width, z - half_height, z + half_height


def arrow_box(arrow):
    """(x min, x max, z min, z max) of an arrow: its start to its tip, widened by half
    its head's diameter."""
    start = np.array(xyz(arrow['pose']['position']))
    tip = start + (arrow['shaft_length'] + arrow['head_length']) * \
        rotate(arrow['pose']['orientation'], [1, 0, 0])
    pad = 0.5 * max(arrow['head_diameter'], arrow['shaft_diameter'])
    return (min(start[0], tip[0]) - pad, max(start[0], tip[0]) + pad,
            min(start[2], tip[2]) - pad, max(start[2], tip[2]) + pad)


def with_jaw_force(batch, force):
    """``batch`` with both jaw force markers ``force`` (N) long in the markers'
    ARROW_SCALE (their directions kept) and the fruit state's grip force ``force``."""
    batch = dict(batch)
    array = copy.deepcopy(batch['markers'])
    for marker in array.markers:
        if marker.ns == 'jaw_forces' and marker.action == Marker.ADD:
            start, end = marker.points
            d = np.array([end.x - start.x, end.y - start.y, end.z - start.z])
            end.x, end.y, end.z = (np.array([start.x, start.y, start.z])
                                   + messages.ARROW_SCALE * force * d / np.linalg.norm(d))
    batch['markers'] = array
    state = copy.deepcopy(batch['fruit/state'])
    state.grip_force = force
    batch['fruit/state'] = state
    return batch


@pytest.fixture(scope='module', params=[(None, None), ('strawberry', None),
                                        (None, 'fin_ray')],
            ids=['apple', 'strawberry', 'fin_ray'])
def grasp(request, squeezed):
    """The default grasp, a small fruit's (the labels sit closer), a Fin Ray's (the
    arrows start at its base, behind the fruit's side)."""
    return squeezed if request.param == (None, None) else squeeze(*request.param)


def overlapping(a, b):
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def test_jaw_force_arrows_stay_clear_of_the_labels_at_any_force(grasp):
    """At a light, the default and the largest grip force (and beyond) the jaw force
    arrows reach neither the colour bar's labels (at any lift: their x ranges are apart)
    nor the state text above the fruit; a larger force draws a longer arrow and the
    state text gives the force exactly. At ARROW_SCALE's 5 mm per N the arrows ran
    into the labels from about 12 N on and were 1 m long at 200 N."""
    context, batch = grasp
    legend = PressureLegend.beside(context)
    lengths = []
    for force in FORCES:
        update = decode_foxglove(scene_of_batch(with_jaw_force(batch, force), legend, 0))
        entities = {e['id']: e for e in update['entities']}
        arrows = [e['arrows'][0] for e in update['entities']
                  if e['id'].startswith('jaw_forces/')]
        assert len(arrows) == 2
        labels = [text_box(t) for t in entities['legend/pressure']['texts']]
        state = entities['legend/state']['texts'][0]
        assert f'grip {force:.2f} N' in state['text']
        for arrow in arrows:
            box = arrow_box(arrow)
            for label in labels:   # the fruit and the jaws rise, the colour bar stays
                assert box[1] < label[0] or label[1] < box[0], (force, box, label)
            assert not overlapping(box, text_box(state)), (force, box, text_box(state))
        lengths.append(max(a['shaft_length'] + a['head_length'] for a in arrows))
    assert all(a < b for a, b in zip(lengths, lengths[1:])), lengths
    assert lengths[-1] < ARROW_CAP


def test_a_jaw_force_arrow_is_5_mm_per_newton_when_small_and_saturates():
    assert jaw_arrow_length(0.0) == 0.0
    assert jaw_arrow_length(0.01) == pytest.approx(0.01 * messages.ARROW_SCALE, rel=1e-2)
    assert jaw_arrow_length(5.0) == pytest.approx(0.5 * ARROW_CAP)
    lengths = [jaw_arrow_length(f) for f in (1.0, 12.0, 200.0, 1e4, 1e5)]
    assert all(a < b < ARROW_CAP for a, b in zip(lengths, lengths[1:]))
