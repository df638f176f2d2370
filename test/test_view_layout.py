"""The shipped Foxglove layout frames the live view's 3D scene.

Foxglove's 3D panel fills every camera field the layout leaves out from its own
defaults and orbits the camera about ``targetOffset`` (``target`` is the followed
frame's pose, which it sets itself). The defaults and the camera placement below are
those of Foxglove Studio's open source 3D panel (``camera.ts`` ``DEFAULT_CAMERA_STATE``,
``Renderer`` ``#updateCameras``), which its fork Lichtblick keeps.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.convert import messages
from gripper_sim.view.scene import PressureLegend, scene_of_batch
from gripper_sim.workflows.factory import make_simulation
from view_client import decode_foxglove

SHIPPED = Path(__file__).resolve().parent.parent / 'config/foxglove/gripper_sim_layout.json'
FOXGLOVE_DEFAULT_CAMERA = {'distance': 20.0, 'perspective': True, 'phi': 60.0,
                           'target': [0, 0, 0], 'targetOffset': [0, 0, 0],
                           'targetOrientation': [0, 0, 0, 1], 'thetaOffset': 45.0,
                           'fovy': 45.0, 'near': 0.5, 'far': 5000.0}
#: width / height of the 3D panel: it takes 3/5 of the window's width, so on a
#: 1280 x 1000 window it is narrower than tall
ASPECT = 0.8
LIFT = 0.03   # m, the README's grasp lifts the fruit and jaws this far


class Camera:
    """Foxglove's perspective camera of a layout's ``cameraState``, in frame ``world``."""

    def __init__(self, state: dict, aspect: float = ASPECT):
        self.state = {**FOXGLOVE_DEFAULT_CAMERA,
                      **{k: v for k, v in state.items() if v is not None}}
        s = self.state
        phi, theta = math.radians(s['phi']), -math.radians(s['thetaOffset'])
        r = s['distance']
        # three.js Spherical (polar angle from +y), then turned +90 degrees about x (z up)
        x, y, z = (r * math.sin(phi) * math.sin(theta), r * math.cos(phi),
                   r * math.sin(phi) * math.cos(theta))
        self.target = np.array(s['targetOffset'], dtype=float)
        self.position = np.array([x, -z, y]) + self.target
        forward = self.target - self.position
        self.forward = forward / np.linalg.norm(forward)
        right = np.cross(self.forward, [0.0, 0.0, 1.0])
        self.right = right / np.linalg.norm(right)
        self.up = np.cross(self.right, self.forward)
        self.tan_half = math.tan(math.radians(s['fovy']) / 2.0)
        self.aspect = aspect

    def project(self, point) -> tuple[float, float, float]:
        """(x, y) in the view, -1 to 1 edge to edge, and the depth (m) of ``point``."""
        d = np.asarray(point, dtype=float) - self.position
        depth = float(d @ self.forward)
        return (float(d @ self.right) / (depth * self.tan_half * self.aspect),
                float(d @ self.up) / (depth * self.tan_half), depth)

    def sees(self, point) -> bool:
        x, y, depth = self.project(point)
        return (self.state['near'] < depth < self.state['far']
                and abs(x) <= 1.0 and abs(y) <= 1.0)


def shipped_camera() -> Camera:
    layout = json.loads(SHIPPED.read_text())
    panel = layout['content']['items'][0]['content']
    assert panel['panelType'] == 'ThreeDee'
    return Camera(panel['config']['cameraState'])


def _rotate(q: dict, v) -> np.ndarray:
    u = np.array([q['x'], q['y'], q['z']], dtype=float)
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + q['w'] * v)


def _at(pose: dict, local) -> np.ndarray:
    p = pose['position']
    return _rotate(pose['orientation'], local) + [p['x'], p['y'], p['z']]


def geometry_points(entity: dict) -> list[np.ndarray]:
    """The points of an entity's shapes (lines, triangles, cube corners, arrow ends)."""
    points = []
    for shape in entity['lines'] + entity['triangles']:
        points += [_at(shape['pose'], [p['x'], p['y'], p['z']]) for p in shape['points']]
    for cube in entity['cubes']:
        s = cube['size']
        points += [_at(cube['pose'], [a * s['x'] / 2, b * s['y'] / 2, c * s['z'] / 2])
                   for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]
    for arrow in entity['arrows']:
        length = arrow['shaft_length'] + arrow['head_length']
        points += [_at(arrow['pose'], [0, 0, 0]), _at(arrow['pose'], [length, 0, 0])]
    return points


def text_anchors(entity: dict) -> list[np.ndarray]:
    return [_at(text['pose'], [0, 0, 0]) for text in entity['texts']]


#: Foxglove draws a text's font_size as its line height, monospace, a character at most
#: this fraction of the line height wide, centred on its pose (a billboard: facing the
#: camera) over an opaque box
CHARACTER_WIDTH = 0.55


def text_corners(text: dict, camera: Camera, lift) -> list[np.ndarray]:
    """The corners (frame world) of a billboard text's box seen by ``camera``."""
    lines = text['text'].split('\n')
    half_width = 0.5 * CHARACTER_WIDTH * text['font_size'] * max(len(s) for s in lines)
    half_height = 0.5 * text['font_size'] * len(lines)
    centre = _at(text['pose'], [0, 0, 0]) + lift
    return [centre + a * half_width * camera.right + b * half_height * camera.up
            for a in (-1, 1) for b in (-1, 1)]


@pytest.fixture(scope='module')
def scenes():
    """The decoded scenes of a 2D and a 3D squeeze at 8 N (the README's grasp force)."""
    out = {}
    for dimension, overrides in ((2, ['fruit.nodes=32']),
                                 (3, ['dimension=3', 'fruit.mesh.subdivisions=3',
                                      'sim.dt=0.002'])):
        config = load_config(overrides=overrides)
        sim = make_simulation(config)
        context = messages.MessageContext.from_config(config, initial=sim.last)
        sim.command_force(8.0)
        result = sim.last
        for _ in range(20000):
            result = sim.step()
            context.observe(result)
            if result.grip_force > 7.0:
                break
        assert result.grip_force > 7.0, 'the jaws never squeezed'
        batch = messages.build_messages(result, context)
        out[dimension] = decode_foxglove(scene_of_batch(batch, PressureLegend.beside(context),
                                                        0))
    return out


@pytest.mark.parametrize('dimension', [2, 3])
@pytest.mark.parametrize('lift', [0.0, LIFT])
def test_the_layout_camera_sees_the_whole_scene(scenes, dimension, lift):
    """Every shape of the scene (but the table, wider than any view of the fruit) and
    every label's anchor is between the clipping planes and inside the view, at rest
    and lifted, with the fruit large enough to watch (a tenth of the view's width)."""
    camera = shipped_camera()
    raised = np.array([0.0, 0.0, lift])
    entities = {e['id']: e for e in scenes[dimension]['entities']}
    for name, entity in entities.items():
        moved = np.zeros(3) if name.startswith('legend/pressure') else raised
        if name.startswith('table'):
            centre = _at(entity['cubes'][0]['pose'], [0, 0, 0])
            assert camera.sees(centre), name
            assert all(camera.project(p)[2] > camera.state['near']
                       for p in geometry_points(entity)), name
            continue
        for point in geometry_points(entity) + text_anchors(entity):
            assert camera.sees(point + moved), (name, point, camera.project(point + moved))
    fruit = next(e for name, e in entities.items() if name.startswith('fruit_'))
    xs = [camera.project(p + raised)[0] for p in geometry_points(fruit)]
    assert max(xs) - min(xs) > 0.2   # of the view's width 2


@pytest.mark.parametrize('dimension', [2, 3])
@pytest.mark.parametrize('lift', [0.0, LIFT])
def test_every_label_is_in_view_and_clear_of_the_others(scenes, dimension, lift):
    """The legend's labels and the state text lie wholly inside the layout's view,
    and no two overlap (each is drawn on an opaque box)."""
    camera = shipped_camera()
    boxes = []
    for entity in scenes[dimension]['entities']:
        moved = np.zeros(3) if entity['id'] == 'legend/pressure' else np.array([0, 0, lift])
        for text in entity['texts']:
            corners = text_corners(text, camera, moved)
            assert all(camera.sees(c) for c in corners), \
                (text['text'], [camera.project(c) for c in corners])
            xs, ys, _ = zip(*(camera.project(c) for c in corners))
            boxes.append((text['text'], min(xs), max(xs), min(ys), max(ys)))
    assert len(boxes) >= 5
    for k, (a, ax0, ax1, ay0, ay1) in enumerate(boxes):
        for b, bx0, bx1, by0, by1 in boxes[k + 1:]:
            assert ax1 < bx0 or bx1 < ax0 or ay1 < by0 or by1 < ay0, (a, b)
