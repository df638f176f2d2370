"""The soft-body step's compiled set-up and outputs (``core.soft_step_kernels``) give
every number the barriers' own Python steps give."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core import barrier
from gripper_sim.core.simulation import Simulation
from gripper_sim.workflows.grasp import GraspSequence, run_grasp


def _grasp(finger: str, python_set_up: bool, monkeypatch, spy_outputs: list | None = None):
    """(every step's fruit and finger positions, velocities and contact forces, the
    Newton iterations, the steps set up compiled, the outcome) of a short grasp-and-lift
    with ``finger``; with ``python_set_up`` every step set up by ``set_up_starts`` and
    ``begin_step`` (``begin_soft_step`` declines); with ``spy_outputs`` each compiled
    output checked against the barrier's own (the differences appended)."""
    compiled_set_ups = []
    begin = barrier.BarrierContact.begin_soft_step

    def counted_begin(self, *args):
        set_up = None if python_set_up else begin(self, *args)
        compiled_set_ups.append(set_up is not None)
        return set_up
    monkeypatch.setattr(barrier.BarrierContact, 'begin_soft_step', counted_begin)
    if spy_outputs is not None:
        outputs = barrier.BarrierContact.soft_outputs

        def checked_outputs(self, q, x_n, dt, solved_reaction, fixed_dofs):
            v, reaction, partner, forces = outputs(self, q, x_n, dt, solved_reaction,
                                                  fixed_dofs)
            own_reaction = np.zeros(q.size)
            own_reaction[fixed_dofs] = solved_reaction[fixed_dofs]
            own = ((q.reshape(-1, 2) - x_n) / dt, own_reaction.reshape(-1, 2),
                   self.partners(q), self.contact_forces(q))
            spy_outputs.append([name for name, a, b in zip(
                ('v', 'reaction', 'partner', 'forces'), (v, reaction, partner, forces), own)
                if a.tobytes() != b.tobytes()])
            return v, reaction, partner, forces
        monkeypatch.setattr(barrier.BarrierContact, 'soft_outputs', checked_outputs)
    config = load_config(overrides=[f'gripper.finger.type={finger}'])
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
    sim = Simulation(config)
    compiled_set_ups.clear()  # (the settling steps)
    states, iterations = [], []

    def on_step(result, phase):
        states.append(np.concatenate([sim.q.ravel(), sim.v.ravel(), sim.contact_forces.ravel(),
                                      sim._finger.positions.ravel(),
                                      sim._finger.velocities.ravel(),
                                      sim._finger.contact_forces.ravel()]))
        iterations.append(result.newton_iterations)
    summary = run_grasp(sim, GraspSequence(sim, 4.0, lift_height=0.005, hold_time=0.05),
                        on_step=on_step)
    return states, iterations, compiled_set_ups, summary['outcome']


@pytest.mark.parametrize('finger', ['fin_ray', 'solid_pad'])
def test_the_compiled_set_up_repeats_the_barriers_own_to_the_bit(finger, monkeypatch):
    """A grasp whose steps are set up by ``soft_step_kernels.begin`` (the fruit's
    barrier and the Fin Ray's self-contact in one call) against one set up by
    ``set_up_starts`` and ``begin_step``: every step's numbers the same to the bit."""
    compiled = _grasp(finger, False, monkeypatch)
    own = _grasp(finger, True, monkeypatch)
    assert compiled[3] == own[3] == 'held'
    assert compiled[1] == own[1]
    assert len(compiled[0]) == len(own[0]) > 100
    for step, (a, b) in enumerate(zip(compiled[0], own[0])):
        assert a.tobytes() == b.tobytes(), f'step {step}'
    # the compiled call set up nearly every step (the others sought the quiet region)
    assert sum(compiled[2]) > 0.95 * len(compiled[2])
    assert not any(own[2])


def test_the_compiled_outputs_are_the_barriers_own():
    """Each step's compiled outputs (velocities, base reactions, partners, contact
    forces) are what the barrier's own methods and numpy's arithmetic give."""
    differences = []
    with pytest.MonkeyPatch.context() as monkeypatch:
        _grasp('fin_ray', False, monkeypatch, differences)
    assert len(differences) > 100
    assert all(not names for names in differences), next(n for n in differences if n)


def _measured(held: bool, monkeypatch) -> list:
    """Every step's measures of a short Fin Ray grasp (deformation, damage, grip, slip,
    centroid), with the fruit's measures from ``soft_step_kernels.held_measures`` or, if
    not ``held``, from the Python route's calls one by one."""
    from gripper_sim.core.facade import SimulationFacade
    if not held:
        monkeypatch.setattr(SimulationFacade, '_held_measures', lambda self, x, obstacle: None)
    config = load_config(overrides=['gripper.finger.type=fin_ray'])
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
    sim = Simulation(config)
    rows = []

    def on_step(result, phase):
        shape, damage = result.deformation, result.damage
        rows.append((shape.compression, shape.compression_ratio, shape.max_skin_strain,
                     shape.contact_length, shape.peak_contact_pressure,
                     shape.node_pressure.tobytes(), damage.pressure, damage.peak_pressure,
                     damage.bruised_length, damage.node_pressure.tobytes(), result.grip_force,
                     result.slip_distance, result.centroid.tobytes()))
    run_grasp(sim, GraspSequence(sim, 4.0, lift_height=0.005, hold_time=0.05),
              on_step=on_step)
    return rows


def test_the_compiled_fruit_measures_are_the_python_routes(monkeypatch):
    """The fruit's measures after a soft-body step in one compiled call (normal forces,
    jaw sides, held length, outline measures) give every step's deformation, damage,
    grip and slip to the bit of the calls one by one."""
    compiled = _measured(True, monkeypatch)
    with pytest.MonkeyPatch.context() as patched:
        own = _measured(False, patched)
    assert len(compiled) == len(own) > 100
    for step, (a, b) in enumerate(zip(compiled, own)):
        assert a == b, f'step {step}'
    assert max(row[3] for row in compiled) > 0.01  # the fingers held the fruit
