"""The jaw plates the figures draw hold the fingers where the simulation holds them.

A deformable finger's base nodes are fixed to its jaw (``FingerBody.base_nodes``, moved
with the jaw by ``SoftFingers.base_targets``): the drawn plate must carry them on its
face. A Fin Ray's base is the top of the finger (``geometry.fin_ray``), so its plate is
on top of the finger, not beside it; a solid pad's base is its back face, the plate
behind it; a flat jaw's plate has its face at the jaw face (where the gap is measured).
Expected positions come from the simulation's own step results and finger bodies, never
from the drawing code.
"""
from __future__ import annotations

import numpy as np
import pytest

import rclpy  # noqa: F401
import gripper_sim_interfaces.msg  # noqa: F401

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.convert.messages import MessageContext, build_messages  # noqa: E402
from gripper_sim.core.soft_fingers import finger_body  # noqa: E402
from gripper_sim.core3d.soft_fingers3d import DEFORMABLE_FINGERS_3D  # noqa: E402
from gripper_sim.recording.analysis import figures, read_time_series  # noqa: E402
from gripper_sim.recording.analysis.frames import frame_of, read_frames  # noqa: E402
from gripper_sim.recording.analysis.series import find_topics  # noqa: E402
from gripper_sim.recording.analysis.summary import summarize  # noqa: E402
from gripper_sim.recording.offline import SimRecorder  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402

pytestmark = pytest.mark.ros

#: mm, how far a base node may lie from the drawn plate's outline (float32 markers)
ON_PLATE_MM = 1e-3


def recorded_close(path, finger: str):
    """The 2D apple's jaws closing on it and rising a little with ``finger``, recorded as
    the node publishes it; (config, the step results, one per recorded row)."""
    config = load_config(finger=finger)
    sim = make_simulation(config)
    results = [sim.last]
    with SimRecorder(path, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        sim.add_observer(results.append)
        sim.command_gap(0.06)
        sim.command_lift(sim.last.lift + 0.004)
        sim.run(0.15)
    return config, results


def drawn_plates(path, rows: list[int]) -> tuple[list, list]:
    """(frames of ``rows``, per frame the two 'jaw' rectangles of ``outline_snapshots``'
    pressure row as (x0, z0, x1, z1) mm, sorted along x)."""
    with BagReader(path) as bag:
        topics = find_topics(bag)
        series = read_time_series(bag, topics)
        bruise = float(load_config()['fruit.bruise_pressure'])
        frames = read_frames(bag, topics['markers'], series, rows, bruise)
    fig = figures.outline_snapshots(series, frames, summarize(series, bruise_pressure=bruise))
    axes = [ax for ax in fig.axes
            if any(c.get_gid() == 'fruit pressure' for c in ax.collections)]
    plates = []
    for ax in axes:
        rects = [p for p in ax.patches if p.get_gid() == 'jaw']
        boxes = [(r.get_x(), r.get_y(), r.get_x() + r.get_width(), r.get_y() + r.get_height())
                 for r in rects]
        plates.append(sorted(boxes))
    return frames, plates


def distance_to_box(points: np.ndarray, box) -> np.ndarray:
    """(k,) distance of (k, 2) points (x, z) to the closed rectangle (x0, z0, x1, z1)."""
    x0, z0, x1, z1 = box
    dx = np.maximum(np.maximum(x0 - points[:, 0], points[:, 0] - x1), 0.0)
    dz = np.maximum(np.maximum(z0 - points[:, 1], points[:, 1] - z1), 0.0)
    return np.hypot(dx, dz)


def inside_box(points: np.ndarray, box, margin: float) -> np.ndarray:
    """(k,) bool: (k, 2) points more than ``margin`` inside the rectangle."""
    x0, z0, x1, z1 = box
    return ((points[:, 0] > x0 + margin) & (points[:, 0] < x1 - margin)
            & (points[:, 1] > z0 + margin) & (points[:, 1] < z1 - margin))


@pytest.mark.parametrize('finger', ['fin_ray', 'solid_pad'])
def test_the_drawn_plates_carry_the_deformable_fingers_base_nodes(tmp_path, finger):
    path = tmp_path / f'{finger}.mcap'
    config, results = recorded_close(path, finger)
    body = finger_body(config, float(config['fruit.depth'] or 0.04))
    m = body.n_nodes
    free = np.setdiff1d(np.arange(m), body.base_nodes)
    last = len(results) - 1
    frames, plates = drawn_plates(path, [0, last])
    assert [f.row for f in frames] == [0, last] and len(plates) == 2
    for frame, boxes in zip(frames, plates):
        result = results[frame.row]
        assert frame.time == pytest.approx(result.time)
        assert len(boxes) == 2
        positions = 1e3 * result.fingers.positions
        for side, box in zip((np.arange(m), m + np.arange(m)), boxes):
            base = positions[side[body.base_nodes]]
            assert np.max(distance_to_box(base, box)) < ON_PLATE_MM, (
                f'{finger} base nodes off the drawn plate {box} (mm) at t = {frame.time}')
            # on its face, not inside it: the free nodes are all out of the plate
            assert not np.any(inside_box(positions[side[free]], box, ON_PLATE_MM))
    if finger == 'fin_ray':   # its base is the top of the finger: the plate is above it
        top = 1e3 * float(results[last].fingers.positions[:, 1].max())
        assert all(box[1] == pytest.approx(top, abs=ON_PLATE_MM) for box in plates[-1])


def test_a_flat_jaws_drawn_plate_has_its_face_at_the_jaw_face(tmp_path):
    path = tmp_path / 'flat.mcap'
    config, results = recorded_close(path, 'flat')
    last = len(results) - 1
    frames, plates = drawn_plates(path, [last])
    (left, right), result = plates[0], results[last]
    height = 1e3 * config['gripper.jaw_height']
    assert left[2] == pytest.approx(1e3 * result.left_jaw_x, abs=ON_PLATE_MM)
    assert right[0] == pytest.approx(1e3 * result.right_jaw_x, abs=ON_PLATE_MM)
    for box in (left, right):
        assert box[3] - box[1] == pytest.approx(height, abs=ON_PLATE_MM)
        assert 0.5 * (box[1] + box[3]) == pytest.approx(1e3 * result.lift, abs=ON_PLATE_MM)


def test_the_3d_fin_rays_plates_carry_its_base_nodes():
    """The 3D figures and the report draw the same ``jaws`` boxes (``Frame.jaws``)."""
    config = load_config(finger='fin_ray',
                         overrides={'dimension': 3, 'fruit.mesh.subdivisions': 4})
    sim = make_simulation(config)
    result = sim.last
    context = MessageContext.from_config(sim.config, initial=result)
    frame = frame_of(build_messages(result, context)['markers'], 0, result.time,
                     context.bruise_pressure)
    body = DEFORMABLE_FINGERS_3D['fin_ray'](sim.config)
    m = body.n_nodes
    boxes = sorted(frame.jaws, key=lambda b: b.centre[0])
    assert len(boxes) == 2
    for side, box in zip((np.arange(m), m + np.arange(m)), boxes):
        low, high = box.bounds()
        base = result.fingers.positions[side[body.base_nodes]]
        assert np.all(base >= low - 1e-6) and np.all(base <= high + 1e-6)
        # on the plate's lower face, the finger hanging below it
        assert base[:, 2] == pytest.approx(low[2], abs=1e-6)
        others = np.delete(result.fingers.positions[side], body.base_nodes, axis=0)
        assert np.all(others[:, 2] < low[2] - 1e-6)
