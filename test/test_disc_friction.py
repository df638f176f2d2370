"""The lagged Coulomb friction of a finger's nodes on a rigid disc
(``core.finger_indent.DiscFriction``): the Coulomb law, its derivatives, bad input."""
import numpy as np
import pytest

from gripper_sim.core.barrier import BarrierSettings
from gripper_sim.core.finger_indent import DiscBarrier, DiscFriction, indent_disc

RADIUS = 0.02
SETTINGS = BarrierSettings(dhat=1e-5, stiffness=1.0)


def _touching(mu=0.3, eps=1e-6):
    """Three nodes 2 um off a disc at the origin (at -30, 0 and 30 deg), lagged there."""
    angles = np.radians([-30.0, 0.0, 30.0])
    x = (RADIUS + 2e-6) * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    disc = DiscBarrier(np.arange(3), 3, RADIUS, SETTINGS)
    friction = DiscFriction(disc, mu, eps)
    friction.lag(x.ravel())
    return x, disc, friction, angles


def test_a_sliding_node_drags_the_disc_with_mu_times_its_normal_force():
    x, disc, friction, angles = _touching()
    normal = np.hypot(*disc.node_forces(x.ravel()).T)
    assert np.all(normal > 0)
    tangents = np.stack([-np.sin(angles), np.cos(angles)], axis=1)
    slid = x + 1e-4 * tangents                      # 0.1 mm along each tangent
    drag = friction.node_forces(slid.ravel())
    assert np.allclose(drag, 0.3 * normal[:, None] * tangents, rtol=1e-12)


def test_a_slip_below_eps_sticks_with_less_than_the_coulomb_force():
    x, disc, friction, angles = _touching()
    normal = np.hypot(*disc.node_forces(x.ravel()).T)
    tangents = np.stack([-np.sin(angles), np.cos(angles)], axis=1)
    drag = np.hypot(*friction.node_forces((x - 2e-7 * tangents).ravel()).T)
    # f1(y) = 2 y / eps - y^2 / eps^2 at y = 0.2 eps: 0.36 of the sliding force
    assert np.allclose(drag, 0.36 * 0.3 * normal, rtol=1e-9)


def test_moving_the_disc_with_the_nodes_is_no_slip():
    x, disc, friction, angles = _touching()
    normal = np.hypot(*disc.node_forces(x.ravel()).T)
    shift = np.array([3e-4, -2e-4])
    disc.centre = disc.centre + shift
    drag = np.hypot(*friction.node_forces((x + shift).ravel()).T)
    assert np.all(drag < 1e-9 * 0.3 * normal), 'round-off of the shift only'
    tangents = np.stack([-np.sin(angles), np.cos(angles)], axis=1)
    drag = np.hypot(*friction.node_forces((x + shift + 1e-5 * tangents).ravel()).T)
    assert np.allclose(drag, 0.3 * normal, rtol=1e-12), 'slipping on the moved disc'


def test_gradient_and_hessian_match_finite_differences():
    x, _, friction, angles = _touching(eps=1e-5)
    rng = np.random.default_rng(3)
    q = (x + 4e-6 * rng.standard_normal(x.shape)).ravel()   # slips within eps: sticking
    grad = np.zeros(q.size)
    data = np.zeros(3 * 4)
    scatter = np.arange(12).reshape(3, 4)
    friction.evaluate_into(q, grad, data, scatter)
    h = 1e-9
    for dof in range(q.size):
        step = np.zeros(q.size)
        step[dof] = h
        up, down = np.zeros(q.size), np.zeros(q.size)
        value_up, _ = friction.evaluate_into(q + step, up, np.zeros(1), scatter, False)
        value_down, _ = friction.evaluate_into(q - step, down, np.zeros(1), scatter, False)
        assert (value_up - value_down) / (2 * h) == pytest.approx(grad[dof], rel=1e-5,
                                                                    abs=1e-12)
        node, axis = divmod(dof, 2)
        column = (up - down)[2 * node:2 * node + 2] / (2 * h)
        block = data[4 * node:4 * node + 4].reshape(2, 2)
        assert np.allclose(block[:, axis], column, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize('mu', [-0.2, float('nan'), float('inf')])
def test_indent_disc_refuses_a_bad_friction_coefficient(mu):
    with pytest.raises(ValueError, match='friction coefficient'):
        indent_disc(None, np.arange(1), np.zeros(2), RADIUS, np.array([1.0, 0.0]), 1e-3, 1,
                    SETTINGS, friction=mu)
