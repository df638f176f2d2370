"""The fast path's step results build their rarely read parts (velocities, contact forces
and sticking, slipping, centroid, jaw wrenches, energies, damage contact patches) on first
read, with the values an eager build gives, and pickle and copy as plain results; a run's
observers share one computation of a step's contact pressures."""
import copy
import dataclasses
import pickle

import numpy as np

from gripper_sim.configuration import load_config
from gripper_sim.core import contact as cm
from gripper_sim.core import peaks
from gripper_sim.core.damage import Damage
from gripper_sim.core.results import StepResult
from gripper_sim.core.simulation import Simulation
from gripper_sim.workflows.grasp import GraspSequence

DEFERRED = ('velocities', 'contact_forces', 'contact_sticking', 'slipping', 'centroid',
            'left_wrench', 'right_wrench', 'energies')


def _gripped_result() -> tuple[Simulation, StepResult]:
    """A step of a grasp with both jaws on the default apple (shell, 24 nodes)."""
    sim = Simulation(load_config(overrides=['fruit.nodes=24']))
    assert sim._fast is not None
    sequence = GraspSequence(sim, 3.0, lift_height=0.01, hold_time=0.05)
    while True:
        result = sim.step()
        sequence.update(result)
        if result.in_contact_with('left_jaw') and result.in_contact_with('right_jaw') and (
                result.grip_force > 1.0):
            return sim, result


def _as_tuple(value):
    if isinstance(value, np.ndarray):
        return ('array', value.shape, tuple(value.ravel().tolist()))
    if dataclasses.is_dataclass(value):
        return tuple(_as_tuple(getattr(value, f.name)) for f in dataclasses.fields(value))
    if isinstance(value, tuple):
        return tuple(_as_tuple(v) for v in value)
    return value


def test_deferred_fields_are_built_on_first_read_with_the_eager_values():
    sim, result = _gripped_result()
    assert not any(name in vars(result) for name in DEFERRED)  # nobody read them yet
    assert 'contacts' not in vars(result.damage)
    # what the measures of the state give eagerly (Simulation._measure's reference path
    # builds each field; the fast path's kernel measures are compared in test_fast_path)
    v, grip = sim.v, sim.gripper_state
    np.testing.assert_array_equal(result.velocities, v)
    assert result.velocities is not v  # a copy, as the eager build gives
    np.testing.assert_array_equal(result.contact_forces, sim.contact_forces)
    np.testing.assert_array_equal(result.contact_sticking, sim.contacts.mode == cm.STICK)
    assert result.contact_sticking.any()  # the jaws hold the fruit
    assert result.left_wrench.force[0] < 0 < result.right_wrench.force[0]  # pushed apart
    assert result.energies.total == (result.energies.kinetic + result.energies.elastic
                                     + result.energies.gravitational)
    masses = sim._fast.masses
    np.testing.assert_allclose(result.centroid, masses @ result.positions / masses.sum(),
                               rtol=1e-12, atol=1e-15)
    assert result.slipping is sim._fast._sliding(v, result.contact_obstacle, grip,
                                                 sim._fast.face_arrays()[0])
    assert len(result.damage.contacts) >= 2  # a patch on each jaw
    assert all(name in vars(result) for name in DEFERRED)


def test_deferred_results_pickle_copy_and_replace_as_plain_results():
    _, result = _gripped_result()
    for clone in (pickle.loads(pickle.dumps(result)), copy.deepcopy(result)):
        assert type(clone) is StepResult and type(clone.damage) is Damage
        assert _as_tuple(clone) == _as_tuple(result)
    shallow = copy.copy(result)
    assert type(shallow) is StepResult and shallow.damage is result.damage
    assert _as_tuple(shallow) == _as_tuple(result)
    moved = dataclasses.replace(result, step=-1)
    assert moved.step == -1 and _as_tuple(moved.left_wrench) == _as_tuple(result.left_wrench)
    assert isinstance(result, StepResult) and dataclasses.is_dataclass(result)
    assert result == result and repr(result).startswith('StepResult(')


def test_contact_pressures_are_computed_once_per_result(monkeypatch):
    _, result = _gripped_result()
    first = peaks.contact_pressures(result)
    assert first[0] > 0
    calls = []
    monkeypatch.setattr(peaks, '_sites', lambda r: calls.append(r))
    assert peaks.contact_pressures(result) == first and not calls


def test_threads_reading_one_deferred_result_at_once_all_get_its_values():
    # The node's physics thread (the actions' step listeners) and its publisher read the
    # same results: the second reader of a result being filled waits for the first's fill.
    import threading
    import time

    from gripper_sim.core.deferred import build_deferred
    from gripper_sim.core.results import Energies

    fills = []

    def slow_fill():
        fills.append(threading.get_ident())
        time.sleep(0.05)   # long enough for every thread to arrive during the fill
        return dict(kinetic=1.0, elastic=2.0)

    result = build_deferred(Energies, dict(gravitational=3.0), ('kinetic', 'elastic'),
                            slow_fill)
    start = threading.Barrier(4)
    read, errors = [], []

    def reader(name):
        start.wait()
        try:
            read.append(getattr(result, name))
        except Exception as err:  # noqa: BLE001 - the failure this test looks for
            errors.append(repr(err))

    threads = [threading.Thread(target=reader, args=(name,))
               for name in ('kinetic', 'elastic', 'kinetic', 'elastic')]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert sorted(read) == [1.0, 1.0, 2.0, 2.0]
    assert len(fills) == 1
    assert result == Energies(kinetic=1.0, elastic=2.0, gravitational=3.0)
