"""The 2D damage rule is one compiled function (``damage.damage_patches``): the tracker of
the generic route and the compiled step's ``kernels.damage_update`` call it, and it equals
the numpy reference (``reference_damage2d``) to round-off."""
import numpy as np
import pytest

import reference_damage2d as reference
from gripper_sim.configuration import load_config
from gripper_sim.core import kernels
from gripper_sim.core.damage import (P_BODY, P_CX, P_CZ, P_LOAD, P_MODULUS, P_PEAK, P_RADIUS,
                                     P_RE, P_SIZE, DamageTracker)
from gripper_sim.core.fruit import build_fruit

#: four faces: 0 and 1 one body (a concave facet and a padded one), 2 a convex padded
#: face, 3 a deformable finger
GROUPS, CURVATURE = [0, 0, 1, 2], [0.0, -20.0, 5.0, 0.0]
PADDED, DEFORMABLE = [False, True, True, True], [False, False, False, True]


def _tracker(deformable):
    config = load_config(overrides=['fruit.nodes=40', 'fruit.bruise_pressure=2e4'])
    fruit = build_fruit(config)
    return fruit, DamageTracker(fruit, config, GROUPS, CURVATURE, PADDED,
                                face_deformable=DEFORMABLE if deformable else None)


def _states(fruit, seed, count=3):
    """Perturbed outlines with runs of held nodes (one across the outline's start)."""
    rng = np.random.default_rng(seed)
    n = fruit.n_nodes
    for _ in range(count):
        x = fruit.rest_positions + rng.normal(scale=2e-4, size=(n, 2))
        obstacle = -np.ones(n, np.int64)
        for start, length in ((n - 3, 6), (10, 5), (20, 4), (28, 3)):
            obstacle[(start + np.arange(length)) % n] = rng.integers(0, len(GROUPS))
        normal = np.where(obstacle >= 0, rng.uniform(0.0, 2.0, n), 0.0)
        yield x, normal, obstacle


@pytest.mark.parametrize('deformable', [False, True])
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_tracker_equals_the_numpy_reference(seed, deformable):
    fruit, tracker = _tracker(deformable)
    covered = tracker.covered.copy()
    bruised = 0
    for x, normal, obstacle in _states(fruit, seed):
        contacts, node_pressure, pressure, covered = reference.step(tracker, covered, x,
                                                                    normal, obstacle)
        damage = tracker.update(x, normal, obstacle, 0.0)
        assert len(damage.contacts) == len(contacts) >= 2
        assert damage.pressure == pytest.approx(pressure, rel=1e-12)
        np.testing.assert_allclose(tracker.covered, covered, rtol=1e-12, atol=1e-15)
        assert damage.bruised_length == pytest.approx(covered.sum(), rel=1e-12)
        np.testing.assert_allclose(damage.node_pressure, node_pressure, rtol=1e-12, atol=1e-6)
        for got, want in zip(damage.contacts, contacts):
            assert got.body == want.body
            np.testing.assert_allclose(
                [got.load, got.radius, got.peak_pressure, got.equivalent_radius, got.modulus],
                [want.load, want.radius, want.peak_pressure, want.equivalent_radius,
                 want.modulus], rtol=1e-12)
            np.testing.assert_allclose(got.centre, want.centre, rtol=0, atol=1e-15)
        bruised += covered.sum() > 0
    assert bruised  # the cover is exercised
    if deformable:  # a deformable finger's radius is read from its patch, others' kept
        rigid = _tracker(False)[1]
        changed = set()
        for x, normal, obstacle in _states(fruit, seed):
            for (a, _), (b, _) in zip(tracker.contacts(x, normal, obstacle),
                                      rigid.contacts(x, normal, obstacle)):
                if a.equivalent_radius != b.equivalent_radius:
                    changed.add(a.body)
        assert changed == {2}


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_compiled_steps_damage_is_the_trackers(seed):
    """``kernels.damage_update`` (what the compiled step runs) gives the tracker's numbers
    bit for bit: one function behind both."""
    fruit, tracker = _tracker(False)
    n = fruit.n_nodes
    covered = tracker.covered.copy()
    for x, normal, obstacle in _states(fruit, seed):
        damage = tracker.update(x, normal, obstacle, 0.0)
        node_pressure = np.zeros(n)
        patches = np.zeros((n, P_SIZE))
        count, pressure, length = kernels.damage_update(
            x, normal, obstacle, np.asarray(fruit.surface, np.int64),
            np.array(GROUPS, np.int64), np.array(CURVATURE), np.array(PADDED, float),
            tracker.rest_curvature, tracker.bruise_pressure, tracker.rigid_modulus,
            tracker.pad_modulus, covered, node_pressure, patches)
        assert count == len(damage.contacts) >= 2
        assert (pressure, length) == (damage.pressure, damage.bruised_length)
        assert np.array_equal(covered, tracker.covered)
        assert np.array_equal(node_pressure, damage.node_pressure)
        for row, contact in zip(patches[:count], damage.contacts):
            assert row[P_BODY] == contact.body
            assert row[[P_LOAD, P_RADIUS, P_PEAK, P_RE, P_MODULUS]].tolist() == [
                contact.load, contact.radius, contact.peak_pressure,
                contact.equivalent_radius, contact.modulus]
            assert row[[P_CX, P_CZ]].tolist() == contact.centre.tolist()
