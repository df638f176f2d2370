"""The whole-step kernel's plumbing: the fruit's constants packed into three arrays, the
scratch space allocated once and reused, the flesh's stress measured in the kernel."""
from __future__ import annotations

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core import kernels
from gripper_sim.core.simulation import Simulation


def _simulation(model: str, *overrides: str) -> Simulation:
    sim = Simulation(load_config(overrides=[f'fruit.model={model}', 'fruit.nodes=24',
                                            *overrides]))
    assert sim._fast is not None and sim._fast.applies()
    return sim


def _squeezed(sim: Simulation, steps: int = 300) -> Simulation:
    sim.command_force(2.0, 0.05)
    for _ in range(steps):
        sim.step()
    return sim


@pytest.mark.parametrize('model', ['shell', 'solid'])
def test_packed_constants_give_back_every_array(model):
    sim = _simulation(model)
    path = sim._fast
    fconst, iconst, layout = path.constants
    tri, dm_inv, volume, lame, tri_scatter, skin, pattern = path.model['flesh']
    floats = {kernels.KF_MASSES2: path.masses2, kernels.KF_MASSES: path.masses,
              kernels.KF_REST_SEGMENTS: path.rest_segments,
              kernels.KF_SPAR: path.model['spar'], kernels.KF_BPAR: path.model['bpar'],
              kernels.KF_PRESS: path.model['press'], kernels.KF_GRAVITY: path.gravity_grad,
              kernels.KF_DM_INV: dm_inv, kernels.KF_VOLUME: volume, kernels.KF_LAME: lame,
              kernels.KF_SKIN_REST: skin[0], kernels.KF_SKIN_STRETCH: skin[1],
              kernels.KF_SKIN_PHI0: skin[3], kernels.KF_SKIN_BEND: skin[4]}
    ints = {kernels.KI_SURFACE: path.surface, kernels.KI_SKIN_EDGES: path.skin_edges,
            kernels.KI_POS: path.model['pos'], kernels.KI_EDGES: path.model['edges'],
            kernels.KI_TRIPLES: path.model['triples'], kernels.KI_RING: path.model['ring'],
            kernels.KI_TRI: tri, kernels.KI_TRI_SCATTER: tri_scatter,
            kernels.KI_SKIN_S_SCATTER: skin[2], kernels.KI_SKIN_B_SCATTER: skin[5]}
    ints.update({kernels.KI_PATTERN + k: array for k, array in enumerate(pattern)})
    assert len(floats) + len(ints) == kernels.K_SLOTS
    views = {1: kernels._packed1, 2: kernels._packed2, 3: kernels._packed3}
    for table, flat in ((floats, fconst), (ints, iconst)):
        for slot, expected in table.items():
            got = views[expected.ndim](flat, layout, slot)
            assert got.shape == expected.shape, slot
            np.testing.assert_array_equal(got, expected)
    if model == 'solid':  # not trivially empty
        assert len(tri) > 10 and len(pattern[5]) > len(tri)


def test_pack_constants_needs_every_slot():
    with pytest.raises(ValueError, match='slots'):
        kernels.pack_constants([np.zeros(2)], [np.zeros(2, np.int64)])


@pytest.mark.parametrize('model', ['shell', 'solid'])
def test_steps_do_not_depend_on_what_the_scratch_space_held(model):
    clean, spoiled = _simulation(model), _simulation(model)
    clean.command_force(2.0, 0.05)
    spoiled.command_force(2.0, 0.05)
    scratch = spoiled._fast.scratch
    # the Newton matrix's kept factor (storage's last three arrays) and its record at the
    # work array's end are state carried from step to step, not scratch
    kept = kernels.KEPT_PER_NODE * spoiled.fruit.n_nodes + kernels.KEPT_META
    for _ in range(300):
        for array in (scratch[0][:-kept], scratch[4], scratch[3][0]):
            array.fill(np.nan)
        scratch[1][scratch[1].shape[0] // 2:] = -7  # the order (first half) stays
        scratch[2].fill(True)
        clean.step()
        spoiled.step()
    assert clean.last.grip_force > 0.5
    np.testing.assert_array_equal(spoiled.q, clean.q)
    np.testing.assert_array_equal(spoiled.v, clean.v)
    np.testing.assert_array_equal(spoiled.contacts.obstacle, clean.contacts.obstacle)
    assert spoiled.last.grip_force == clean.last.grip_force
    assert spoiled._fast.scratch[0] is scratch[0]  # reused, not reallocated


@pytest.mark.parametrize('model', ['shell', 'solid'])
def test_a_reset_simulation_forgets_the_kept_factor_and_repeats_its_steps(model):
    sim = _simulation(model)
    runs = []
    for _ in range(2):
        sim.reset()
        sim.command_force(2.0, 0.05)
        iterations = []
        for _ in range(10):
            sim.step()
            iterations.append(sim.last.newton_iterations)
        runs.append((sim.q.copy(), iterations))
    np.testing.assert_array_equal(runs[1][0], runs[0][0])
    assert runs[1][1] == runs[0][1]


def test_the_kernels_flesh_stress_is_the_energys_von_mises():
    sim = _squeezed(_simulation('solid'))
    stress = sim._fast._measured[5]
    expected = float(np.max(sim.fruit.flesh.von_mises(sim.q.ravel()), initial=0.0))
    assert stress > 0
    assert stress == expected
    assert sim.last.damage.flesh_stress >= stress
    shell = _squeezed(_simulation('shell'), 10)
    assert shell._fast._measured[5] == 0.0
