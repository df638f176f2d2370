"""The Fin Ray finger's self-contact: its beams and ribs never cross each other.

A 10 mm deep default Fin Ray pressed over the middle third of its front beam to 12 N
(the load ramped over 100 increments of 1 ms, each starting at rest, then held for 100
more: an overdamped motion that follows the finger's snap-through) folds its front beam
onto the members behind it. Without self-contact its members cross; with it
(``FingerBody.self_contact``, the barrier between a vertex and an element of the finger
that share no node) they touch and never cross, at every increment.
"""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.barrier import BarrierSettings
from gripper_sim.core.fin_ray import fin_ray_body
from gripper_sim.core.finger_statics import static_equilibrium
from gripper_sim.core.simulation import Simulation
from gripper_sim.geometry.finger_materials import MATERIALS
from test_fin_ray import _geometry, _press

#: the barrier of the simulation's defaults (contact.ipc.dhat, contact.ipc.stiffness)
SETTINGS = BarrierSettings.from_config(load_config())
GRIP = 12.0


def crossings(x: np.ndarray, edges: np.ndarray) -> int:
    """The pairs of elements ``edges`` (e, 2) that share no node and whose segments cross
    (strictly) at positions ``x`` (n, 2)."""
    a, b = x[edges[:, 0]], x[edges[:, 1]]

    def side(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    a1, b1, a2, b2 = a[:, None], b[:, None], a[None], b[None]
    cross = ((side(a1, b1, a2) * side(a1, b1, b2) < 0)
             & (side(a2, b2, a1) * side(a2, b2, b1) < 0))
    shared = np.any(edges[:, None, :, None] == edges[None, :, None, :], axis=(2, 3))
    return int(np.sum(np.triu(cross & ~shared, 1)))


def smallest_gap(x: np.ndarray, edges: np.ndarray) -> float:
    """m, the smallest distance between a node and an element it is not an end of."""
    a, b = x[edges[:, 0]], x[edges[:, 1]]
    along = b - a
    rel = x[:, None] - a[None]
    t = np.clip(np.sum(rel * along[None], axis=2) / np.sum(along * along, axis=1), 0, 1)
    gap = np.linalg.norm(rel - t[..., None] * along[None], axis=2)
    own = np.any(edges[None, :, :] == np.arange(len(x))[:, None, None], axis=2)
    return float(np.min(np.where(own, np.inf, gap)))


def _fold(self_contact, element: float = 0.002, grip: float = GRIP):
    """(crossings at each increment, the smallest gap at the end m) of the finger with
    rod elements ``element`` m long pressed to ``grip`` N."""
    body = fin_ray_body(_geometry(depth=0.01, element_length=element), MATERIALS['tpu'])
    forces, _ = _press(body, grip, 0.01)
    counts = []
    final = static_equilibrium(body, forces, increments=100, hold=100, step=1e-3,
                               tolerance=1e-6, self_contact=self_contact,
                               on_increment=lambda x: counts.append(
                                   crossings(x, body.rod_edges)))
    return counts, smallest_gap(final.positions, body.rod_edges)


def test_without_self_contact_the_pressed_beams_cross():
    counts, _ = _fold(None)
    assert counts[0] == 0 and max(counts) > 0


@pytest.mark.parametrize('element, grip', [(0.002, GRIP), (0.004, GRIP), (0.002, 16.0)])
def test_with_self_contact_the_beams_touch_and_never_cross(element, grip):
    """Also where the last Newton step of an increment, below the tolerance (1 um), is
    longer than the gap the barrier keeps (0.2-0.5 um): 4 mm elements at 12 N and 2 mm
    at 16 N crossed when such a step was taken whole, past the step bound."""
    counts, gap = _fold(SETTINGS, element, grip)
    assert len(counts) == 200
    assert max(counts) == 0
    assert 0 < gap < 1e-5, 'folded onto the members behind it, not through them'


def test_the_finger_at_rest_feels_no_self_contact():
    body = fin_ray_body(_geometry(), MATERIALS['tpu'])
    barrier = body.self_contact(SETTINGS)
    q = body.rest_positions.ravel()
    barrier.begin_step(body.rest_positions, [], [], 1e-3)
    evaluation = barrier.evaluate(q)
    assert evaluation.value == 0.0 and not np.any(evaluation.gradient)
    assert smallest_gap(body.rest_positions, body.rod_edges) > 100 * SETTINGS.dhat


def test_the_simulation_gives_each_fin_ray_its_self_contact():
    sim = Simulation(load_config(overrides=['gripper.finger.type=fin_ray']))
    barrier = sim._soft.self_contact
    assert barrier in sim.solver.energies
    m = sim._soft.body.n_nodes
    bodies = [set(body.nodes.tolist()) for body in barrier.bodies]
    assert bodies == [set(range(sim.fruit.n_nodes, sim.fruit.n_nodes + m)),
                      set(range(sim.fruit.n_nodes + m, sim.fruit.n_nodes + 2 * m))]
    # the pattern's pairs stay within one finger
    pairs = barrier.pattern_pairs - sim.fruit.n_nodes
    assert np.all((pairs[:, 0] < m) == (pairs[:, 1] < m))


@pytest.mark.parametrize('finger', ['solid_pad'])
def test_a_finger_without_rods_has_no_self_contact(finger):
    sim = Simulation(load_config(overrides=[f'gripper.finger.type={finger}']))
    assert sim._soft.self_contact is None


def test_a_folding_finger_grows_its_self_contact_pattern():
    """The tomato squeezed to 43.8 N (the 2 mm Fin Ray's window trial): each finger's front
    beam lands on members whose nodes lay apart at rest, outside its self-contact's
    Hessian pattern; their couplings were left out of the Newton matrix (5 times too
    stiff along the nodes' joint motion: ``bench/newton_matrix_check.py --pick``), Newton
    crept and the trial failed at its smallest sub-step. A step that fails so grows the
    self-contact's pattern too (``BarrierContact.grow_pattern``): the trial runs through
    (the tomato slips), and a reset goes back to the pattern given."""
    from gripper_sim.workflows.factory import make_simulation
    from gripper_sim.workflows.grasp import evaluate
    from gripper_sim.workflows.scenario import PickAndPlace, load_scenario, scenario_config
    from gripper_sim.workflows.window import trial_setup
    scenario = load_scenario('pick_and_place')
    config, base = trial_setup(scenario_config(scenario, fruit='tomato', finger='fin_ray'),
                               scenario)
    # the window's finger of 2 mm elements (the tomato's default is 4 mm now, whose
    # fingers deliver at most 42.1 N)
    sim = make_simulation({**config, 'gripper.finger.fin_ray.element_length': 0.002})
    barrier = sim._soft.self_contact
    given = barrier.pattern_pairs
    machine = PickAndPlace(sim, base.with_values(close__mode='force', close__force=43.804),
                           until='transport', stop_on_bruise=True)
    evaluation = evaluate(sim, machine, 43.804)
    assert evaluation.outcome != 'solver failed', evaluation.message
    assert evaluation.peak_grip_force == pytest.approx(43.804, rel=0.02)
    grown = barrier.pattern_pairs
    assert len(grown) > len(given)
    m, first = sim._soft.body.n_nodes, sim.fruit.n_nodes
    assert np.all((grown[:, 0] - first < m) == (grown[:, 1] - first < m))  # one finger's
    sim.reset()
    assert barrier.pattern_pairs is given
