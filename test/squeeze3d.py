"""3D squeezes with deformable fingers, watched for crossing surfaces at every step (the
solid pad's and the Fin Ray's tests share them)."""
import ipctk
import numpy as np

from gripper_sim.configuration import load_config
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
