"""The gripper's TF tree and URDF (pure functions): frames follow the jaws, the lift and
the transport; the URDF parses with yourdfpy and its kinematics equal the TF tree."""
from __future__ import annotations

import dataclasses
import io
import subprocess
import sys

import pytest
import yourdfpy

from gripper_sim.configuration import load_config
from gripper_sim.convert.frames import (JOINT_NAMES, WORLD_FRAME, FrameError,
                                        GripperFrames, dynamic_transforms, frame_position,
                                        joint_positions, static_transforms)
from gripper_sim.convert.messages import MessageContext
from gripper_sim.convert.urdf import gripper_urdf
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import CommandError


@pytest.fixture(scope='module')
def moved():
    """Results of a 2D run that closes, lifts and transports the gripper."""
    config = load_config()
    sim = Simulation(config)
    results = [sim.last]
    sim.command_gap(0.05)
    sim.command_lift(sim.last.lift + 0.02, 0.2)
    sim.command_transport(sim.last.gripper_x + 0.03, 0.2)
    for _ in range(150):
        results.append(sim.step())
    return config, results


def _frames(config, results, prefix=''):
    first = results[0]
    outward = -1.0 if first.left_jaw_x <= first.right_jaw_x else 1.0
    return GripperFrames.from_config(config, prefix=prefix, left_outward=outward)


def test_jaw_frames_sit_on_the_jaw_faces_at_the_lift_height(moved):
    config, results = moved
    frames = _frames(config, results)
    last = results[-1]
    assert last.gripper_x != results[0].gripper_x and last.lift != results[0].lift
    for result in (results[0], results[40], last):
        tree = dynamic_transforms(result, frames)
        assert frame_position(tree, 'left_jaw') == pytest.approx(
            (result.left_jaw_x, 0.0, result.lift), abs=1e-12)
        assert frame_position(tree, 'right_jaw') == pytest.approx(
            (result.right_jaw_x, 0.0, result.lift), abs=1e-12)
        assert frame_position(tree, 'gripper_base') == pytest.approx(
            (result.gripper_x, 0.0, result.lift), abs=1e-12)
        q = joint_positions(result, frames)
        assert q['left_jaw_joint'] + q['right_jaw_joint'] == pytest.approx(result.gap)
        assert q['left_jaw_joint'] > 0 and q['right_jaw_joint'] > 0   # open > 0
        assert all(t.rotation == (0.0, 0.0, 0.0, 1.0) for t in tree)


def test_prefixed_trees_share_only_the_world(moved):
    config, results = moved
    trees = [dynamic_transforms(results[-1], _frames(config, results, prefix))
             + static_transforms(_frames(config, results, prefix)) for prefix in ('g1/', 'g2/')]
    children = [{t.child for t in tree} for tree in trees]
    assert not children[0] & children[1]
    assert all(t.parent == WORLD_FRAME or t.parent.startswith('g1/') for t in trees[0])
    assert 'g1/table' in children[0]
    assert frame_position(trees[0], 'g1/left_jaw') == frame_position(trees[1], 'g2/left_jaw')
    for bad in ('/g1/', 'g 1/', 'g1//x', 'é/'):
        with pytest.raises(FrameError, match='not valid'):
            GripperFrames(prefix=bad)


def test_no_tree_from_a_non_finite_result(moved):
    config, results = moved
    broken = dataclasses.replace(results[-1], lift=float('nan'))
    with pytest.raises(FrameError, match='non-finite lift'):
        dynamic_transforms(broken, _frames(config, results))


def test_urdf_parses_and_its_kinematics_equal_the_tf_tree(moved):
    config, results = moved
    frames = _frames(config, results, prefix='g1/')
    text = gripper_urdf(frames)
    model = yourdfpy.URDF.load(io.StringIO(text), build_collision_scene_graph=False,
                               load_meshes=False)
    assert model.validate()
    assert set(model.actuated_joint_names) == set(JOINT_NAMES)
    assert {j.type for j in model.robot.joints} == {'prismatic'}
    assert {link.name for link in model.robot.links} == {
        WORLD_FRAME, 'g1/carriage', 'g1/gripper_base', 'g1/left_jaw', 'g1/right_jaw'}
    for result in (results[0], results[-1]):
        model.update_cfg(joint_positions(result, frames))
        tree = dynamic_transforms(result, frames)
        for frame in ('g1/left_jaw', 'g1/right_jaw', 'g1/gripper_base'):
            placed = model.get_transform(frame, WORLD_FRAME)
            assert tuple(placed[:3, 3]) == pytest.approx(frame_position(tree, frame),
                                                         abs=1e-12)
            assert placed[:3, :3].ravel().tolist() == pytest.approx([1, 0, 0, 0, 1, 0, 0, 0, 1])


@pytest.mark.parametrize('overrides', [[], ['world.table=false'],
                                       ['world.walls=true', 'world.wall_half_width=0.3']])
def test_urdf_joint_limits_are_the_commands_the_simulation_accepts(overrides):
    """A planner reading the URDF plans only lifts and transports the node accepts: each
    limit is accepted, a millimetre beyond it refused."""
    config = load_config(overrides=overrides)
    # the frames of the configuration, and those the node, the recorders and the live
    # view publish robot_description from (``MessageContext.from_config``)
    for frames in (GripperFrames.from_config(config), MessageContext.from_config(config).frames):
        _check_limits(config, frames)


def _check_limits(config, frames):
    model = yourdfpy.URDF.load(io.StringIO(gripper_urdf(frames)),
                               build_collision_scene_graph=False, load_meshes=False)
    sim = Simulation(config)
    for joint, command in (('lift_joint', sim.command_lift),
                           ('transport_joint', sim.command_transport)):
        limit = model.joint_map[joint].limit
        assert limit.lower < limit.upper
        for value in (limit.lower, limit.upper):
            command(value)
        for value in (limit.lower - 1e-3, limit.upper + 1e-3):
            with pytest.raises(CommandError):
                command(value)


def test_the_conversion_imports_no_ros():
    code = ('import sys, gripper_sim.convert.frames, gripper_sim.convert.urdf; '
            'print(any(m.split(".")[0] in ("rclpy", "rosidl_runtime_py") for m in sys.modules))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == 'False'
