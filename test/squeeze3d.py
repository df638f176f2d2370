"""3D squeezes with deformable fingers, watched for crossing surfaces at every step (the
solid pad's and the Fin Ray's tests share them)."""
import ipctk
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core3d import meshes
from gripper_sim.core3d.simulation import Simulation3D


def no_crossing_watch(sim):
    """A list of the smallest distance (m) between the fruit's and the fingers' surfaces
    at each step; raises AssertionError as soon as the two surfaces intersect."""
    barrier = sim._barrier
    distances = []

    def check(result):
        positions = np.vstack([result.positions, result.fingers.positions])
        v = barrier.vertices(positions)
        assert not ipctk.has_intersections(barrier._mesh, v)
        distances.append(barrier.min_distance(positions))

    sim.add_observer(check)
    return distances


def squeeze(overrides, force=2.0, settle=0.1, max_steps=80):
    """(simulation, its result after ``settle`` s at ``force`` N, the watch's distances
    (empty for rigid fingers)): the jaws close in force mode until the grip is within 1 %
    of ``force`` (at most ``max_steps`` steps), then hold it ``settle`` s."""
    sim = Simulation3D(load_config(overrides=overrides))
    watch = no_crossing_watch(sim) if sim._soft is not None else []
    sim.command_force(force)
    for _ in range(max_steps):
        result = sim.step()
        if abs(result.grip_force - force) < 0.01 * force and result.step > 5:
            break
    return sim, sim.run(settle), watch


def assert_squeezed(sim, result, distances, force=2.0):
    """The checks every deformable finger's squeeze passes: the grip met, no crossing and
    no pair closer than 0 at any step, the grip as the base reaction (each jaw's wrench
    along the closing axis), the fruit's force on the fingers equal and opposite to
    theirs on the fruit's nodes they hold (obstacles 0 and 1; the table is the next)."""
    assert result.grip_force == pytest.approx(force, rel=0.01)
    assert len(distances) == result.step and min(distances) > 0.0
    assert -result.left_wrench.force[0] == pytest.approx(force, rel=0.02)
    assert result.right_wrench.force[0] == pytest.approx(force, rel=0.02)
    fingers = result.fingers
    assert fingers.positions.shape == (sim._soft.n_nodes, 3)
    on_fingers = result.contact_obstacle <= 1
    assert fingers.contact_forces.sum(axis=0) == pytest.approx(
        -result.contact_forces[on_fingers].sum(axis=0), abs=1e-9)


def finger_area_difference(sim, result) -> float:
    """The difference between the two fingers' contact areas, in units of their surface's
    largest node area at rest: a finger's area counts its nodes in a pair closer than
    dhat (1 um), so at the rim of the patch a node is in or out whole."""
    body = sim._soft.body
    node_area = meshes.vertex_areas(body.rest_positions, body.surface_triangles,
                                    body.n_nodes).max()
    return float(abs(np.subtract(*result.fingers.contact_area)) / node_area)
