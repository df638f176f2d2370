"""The node's markers of deformable fingers (ns ``soft_fingers``): their outlines, moving
and deforming with them, read back by the recording's report; none for rigid fingers."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.convert.messages import build_messages
from gripper_sim.core.simulation import Simulation
from gripper_sim.recording.analysis.frames import frame_of


def _soft_markers(config):
    sim = Simulation(config)
    array = build_messages(sim.last, config, topics=['markers'])['markers']
    return sim, [m for m in array.markers if m.ns == 'soft_fingers']


def test_the_pads_outlines_are_drawn_where_the_pads_are():
    config = load_config(overrides=['gripper.finger.type=solid_pad'])
    sim, found = _soft_markers(config)
    assert len(found) == 1
    fingers = sim.last.fingers
    points = np.array([(p.x, p.y, p.z) for p in found[0].points])
    # the whole pads: every boundary edge of their meshes, the jaw side too
    assert len(points) == 2 * len(fingers.drawn_edges) > 2 * len(fingers.surface_edges)
    assert np.all(points[:, 1] == 0.0)
    backing = 0.5 * sim.last.gap
    assert np.max(np.abs(points[:, 0])) == pytest.approx(backing)
    # the fronts of the undeformed pads: half the gap (between the backings) less a pad
    front = 0.5 * sim.last.gap - config['gripper.finger.solid_pad.thickness']
    assert np.min(np.abs(points[:, 0])) == pytest.approx(front)
    assert points[:, 2].max() - points[:, 2].min() == pytest.approx(config['gripper.jaw_height'])


def test_rigid_fingers_have_no_soft_finger_marker():
    assert _soft_markers(load_config())[1] == []


def test_the_report_reads_the_fingers_back_from_the_markers():
    config = load_config(overrides=['gripper.finger.type=solid_pad'])
    sim = Simulation(config)
    array = build_messages(sim.last, config, topics=['markers'])['markers']
    frame = frame_of(array, 0, 0.0, config['fruit.bruise_pressure'])
    edges = sim.last.fingers.drawn_edges
    assert frame.finger_lines.shape == (len(edges), 2, 3)
    assert frame.finger_lines[:, :, [0, 2]] == pytest.approx(
        sim.last.fingers.positions[edges])
    rigid = build_messages(Simulation(load_config()).last, load_config(),
                           topics=['markers'])['markers']
    assert frame_of(rigid, 0, 0.0, 2.6e5).finger_lines.shape == (0, 2, 3)


def test_a_fin_ray_is_drawn_whole_beams_ribs_and_base():
    """Both beams and the ribs, joined at the jaw: every rod segment of each finger."""
    config = load_config(overrides=['gripper.finger.type=fin_ray'])
    sim, found = _soft_markers(config)
    fingers = sim.last.fingers
    drawn = {tuple(np.round(p, 12)) for p in
             np.array([(p.x, p.z) for p in found[0].points])}
    nodes = {tuple(np.round(p, 12)) for p in fingers.positions[:, [0, 1]]}
    assert drawn == nodes   # every node of both fingers, not just the front beams'
    assert len(found[0].points) == 2 * len(fingers.drawn_edges)

