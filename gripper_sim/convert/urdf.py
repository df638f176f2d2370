"""The gripper as a URDF string whose links are the TF frames of ``frames`` and whose
joints are the ``/joint_states`` joints (no rclpy).

Links: ``world`` (the shared root), ``<p>carriage``, ``<p>gripper_base``,
``<p>left_jaw``, ``<p>right_jaw``; prismatic joints ``transport_joint`` (x),
``lift_joint`` (z), ``left_jaw_joint`` and ``right_jaw_joint`` (outwards, 0 = jaw face
on the centre line, up to half ``max_gap``). Each jaw link carries a box visual and
collision of the jaw plate where the finger is held (``GripperFrames.plate``, as the
``jaws`` markers draw it): behind the jaw face of a flat finger and a solid pad, behind
the deepest point of a shaped finger's face, on top of a Fin Ray's base (the finger
hangs below it). Published on ``/robot_description``
(transient local), a robot_state_publisher or RViz's RobotModel display places it from
``/joint_states`` or ``/tf``.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

from gripper_sim.convert.frames import WORLD_FRAME, GripperFrames

#: Limits of the joints URDF requires besides their travel (effort N, velocity m/s;
#: the travel is what the simulation accepts, ``GripperFrames.lift_range`` and
#: ``transport_range``).
EFFORT_LIMIT = 1.0e5            # N
VELOCITY_LIMIT = 2.0            # m/s
BASE_SIZE = (0.02, 0.02, 0.02)  # m, a small block to show the gripper centre
MATERIAL = 'jaw_grey'


def _xyz(values) -> str:
    return ' '.join(f'{float(v):.9g}' for v in values)


def _box_link(robot: ET.Element, name: str, size, offset) -> None:
    link = ET.SubElement(robot, 'link', name=name)
    for tag in ('visual', 'collision'):
        element = ET.SubElement(link, tag)
        ET.SubElement(element, 'origin', xyz=_xyz(offset), rpy='0 0 0')
        geometry = ET.SubElement(element, 'geometry')
        ET.SubElement(geometry, 'box', size=_xyz(size))
        if tag == 'visual':
            ET.SubElement(element, 'material', name=MATERIAL)


def _prismatic(robot: ET.Element, name: str, parent: str, child: str, axis, lower: float,
               upper: float) -> None:
    joint = ET.SubElement(robot, 'joint', name=name, type='prismatic')
    ET.SubElement(joint, 'parent', link=parent)
    ET.SubElement(joint, 'child', link=child)
    ET.SubElement(joint, 'origin', xyz='0 0 0', rpy='0 0 0')
    ET.SubElement(joint, 'axis', xyz=_xyz(axis))
    ET.SubElement(joint, 'limit', lower=_xyz([lower]), upper=_xyz([upper]),
                  effort=_xyz([EFFORT_LIMIT]), velocity=_xyz([VELOCITY_LIMIT]))


def jaw_box(frames: GripperFrames, outward: float) -> tuple[tuple, tuple]:
    """(size, offset) of a jaw's plate box in its jaw link (m, x y z): the plate of
    ``frames.plate`` (x towards the fruit, mirrored for the jaw that opens towards
    ``outward``, +1 or -1 along x), over the jaw width along y."""
    (x, z), (size_x, size_z) = frames.plate or (
        (-0.5 * frames.jaw_thickness, 0.0), (frames.jaw_thickness, frames.jaw_height))
    return (size_x, frames.jaw_width, size_z), (-outward * x, 0.0, z)


def gripper_urdf(frames: GripperFrames) -> str:
    """The URDF XML text of the gripper described by ``frames``."""
    robot = ET.Element('robot', name=f'{frames.prefix}gripper_sim')
    ET.SubElement(ET.SubElement(robot, 'material', name=MATERIAL), 'color',
                  rgba='0.45 0.45 0.5 0.8')
    ET.SubElement(robot, 'link', name=WORLD_FRAME)
    ET.SubElement(robot, 'link', name=frames.carriage)
    _box_link(robot, frames.base, BASE_SIZE, (0.0, 0.0, 0.0))
    for frame, outward in ((frames.left_jaw, frames.left_outward),
                           (frames.right_jaw, -frames.left_outward)):
        _box_link(robot, frame, *jaw_box(frames, outward))
    left, right, lift, transport = frames.joint_names
    _prismatic(robot, transport, WORLD_FRAME, frames.carriage, (1, 0, 0),
               *frames.transport_range)
    _prismatic(robot, lift, frames.carriage, frames.base, (0, 0, 1), *frames.lift_range)
    half_gap = frames.max_gap / 2.0
    _prismatic(robot, left, frames.base, frames.left_jaw, (frames.left_outward, 0, 0),
               0.0, half_gap)
    _prismatic(robot, right, frames.base, frames.right_jaw, (-frames.left_outward, 0, 0),
               0.0, half_gap)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'
