"""The URDF's jaw plates hold the fingers where the simulation holds them.

The node's ``robot_description`` (``recording.latched``, from its ``MessageContext``)
gives each jaw link a box, the jaw plate. A deformable finger's base nodes are fixed to
its jaw (``FingerBody.base_nodes``): they must lie on that box's face, the rest of the
finger outside it. A Fin Ray's base is the top of the finger, so its plate sits on top
of the finger, not beside it at the jaw centre as a flat finger's. Expected positions
come from the simulation's own initial state and finger bodies, placed by the URDF's
own joints (yourdfpy) at the state's joint positions.
"""
from __future__ import annotations

import io

import numpy as np
import pytest
import yourdfpy

import rclpy  # noqa: F401

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.convert.frames import WORLD_FRAME, joint_positions  # noqa: E402
from gripper_sim.convert.messages import MessageContext, build_messages  # noqa: E402
from gripper_sim.core.soft_fingers import finger_body  # noqa: E402
from gripper_sim.core3d.soft_fingers3d import DEFORMABLE_FINGERS_3D  # noqa: E402
from gripper_sim.recording.latched import latched_messages  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402

pytestmark = pytest.mark.ros

#: m, how far a base node may lie from the plate box (the URDF writes 9 digits)
ON_PLATE = 1e-8


def published_boxes(sim, result) -> tuple[list, MessageContext]:
    """The URDF the node publishes for ``sim``, placed at ``result``'s joints: per jaw
    (left, right) the (low, high) world corners of its collision box, after checking
    that its visual box is the same."""
    context = MessageContext.from_config(sim.config, initial=result)
    urdf = latched_messages(context.frames)['robot_description'].data
    model = yourdfpy.URDF.load(io.StringIO(urdf), build_collision_scene_graph=False,
                               load_meshes=False)
    model.update_cfg(joint_positions(result, context.frames))
    boxes = []
    for jaw in (context.frames.left_jaw, context.frames.right_jaw):
        link = model.link_map[jaw]
        (collision,), (visual,) = link.collisions, link.visuals
        assert np.allclose(collision.origin, visual.origin)
        assert np.allclose(collision.geometry.box.size, visual.geometry.box.size)
        centre = (model.get_transform(jaw, WORLD_FRAME) @ collision.origin)[:3, 3]
        half = 0.5 * np.asarray(collision.geometry.box.size)
        boxes.append((centre - half, centre + half))
    return boxes, context


def distance_to_box(points: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(k,) distance of (k, d) points to the closed box [low, high] (same d axes)."""
    outside = np.maximum(np.maximum(low - points, points - high), 0.0)
    return np.linalg.norm(outside, axis=1)


def inside_box(points: np.ndarray, low: np.ndarray, high: np.ndarray,
               margin: float) -> np.ndarray:
    """(k,) bool: points more than ``margin`` inside the box on every axis."""
    return np.all((points > low + margin) & (points < high - margin), axis=1)


def check_base_on_plates(positions: np.ndarray, base: np.ndarray, boxes: list,
                         axes: list[int]) -> None:
    """The base nodes of each finger (left first, then right, ``positions`` world, on
    ``axes`` of the 3D boxes) on its jaw's box, its other nodes out of it."""
    m = len(positions) // 2
    free = np.setdiff1d(np.arange(m), base)
    for side, (low, high) in zip((np.arange(m), m + np.arange(m)), boxes):
        low, high = low[axes], high[axes]
        held = positions[side[base]]
        assert np.max(distance_to_box(held, low, high)) < ON_PLATE, (
            f'base nodes {held.min(axis=0)}..{held.max(axis=0)} off the plate box '
            f'{low}..{high} (m)')
        assert not np.any(inside_box(positions[side[free]], low, high, ON_PLATE))


@pytest.mark.parametrize('finger', ['fin_ray', 'solid_pad'])
def test_the_urdf_plates_carry_the_deformable_fingers_base_nodes(finger):
    config = load_config(finger=finger)
    sim = make_simulation(config)
    result = sim.last
    boxes, _ = published_boxes(sim, result)
    body = finger_body(sim.config, float(sim.config['fruit.depth'] or 0.04))
    check_base_on_plates(result.fingers.positions, body.base_nodes, boxes, [0, 2])
    if finger == 'fin_ray':   # the finger hangs below its plate
        top = float(result.fingers.positions[:, 1].max())
        for low, high in boxes:
            assert low[2] == pytest.approx(top, abs=ON_PLATE)
            assert high[2] - low[2] == pytest.approx(config['gripper.jaw_thickness'])


def test_the_urdf_plates_carry_the_3d_fin_rays_base_nodes():
    config = load_config(finger='fin_ray',
                         overrides={'dimension': 3, 'fruit.mesh.subdivisions': 4})
    sim = make_simulation(config)
    result = sim.last
    boxes, _ = published_boxes(sim, result)
    body = DEFORMABLE_FINGERS_3D['fin_ray'](sim.config)
    check_base_on_plates(result.fingers.positions, body.base_nodes, boxes, [0, 1, 2])


def test_a_flat_jaws_urdf_plate_is_behind_its_face():
    sim = make_simulation(load_config(finger='flat'))
    result = sim.last
    (left, right), context = published_boxes(sim, result)
    assert left[1][0] == pytest.approx(result.left_jaw_x, abs=ON_PLATE)
    assert right[0][0] == pytest.approx(result.right_jaw_x, abs=ON_PLATE)
    for low, high in (left, right):
        assert high[0] - low[0] == pytest.approx(context.jaw_thickness)
        assert high[2] - low[2] == pytest.approx(context.jaw_height)
        assert 0.5 * (low[2] + high[2]) == pytest.approx(result.lift, abs=ON_PLATE)


@pytest.mark.parametrize('finger', ['flat', 'arc', 'vgroove', 'soft_pad', 'solid_pad',
                                    'fin_ray'])
def test_the_urdf_plates_are_the_drawn_jaws(finger):
    """RViz shows the URDF's boxes and the ``jaws`` markers together: one plate each
    (along x and z; a 2D marker is as deep as the planar fruit, the URDF's box as the
    jaw is wide)."""
    sim = make_simulation(load_config(finger=finger))
    result = sim.last
    boxes, context = published_boxes(sim, result)
    jaws = [m for m in build_messages(result, context)['markers'].markers
            if m.ns == 'jaws']
    assert len(jaws) == 2
    for marker, (low, high) in zip(sorted(jaws, key=lambda m: m.pose.position.x), boxes):
        position, scale = marker.pose.position, marker.scale
        assert 0.5 * (low + high)[[0, 2]] == pytest.approx([position.x, position.z],
                                                           abs=ON_PLATE)
        assert (high - low)[[0, 2]] == pytest.approx([scale.x, scale.z], abs=ON_PLATE)
