"""The hold threshold at the default lift (0.5 m/s^2) against m (g + a) / (2 mu) (README,
*Grasp window*): at mu_s = mu_k = 0.3 and 0.8, on the apple (134 g) and the plum (50 g):
two real presets whose mass and stiffness both differ (not a denser apple), so the check
is not tuned to one shell.

"Holds" is the grasp window's verdict (``GraspEvaluation.held``): carried to the end and
less than ``window.max_slip`` (1 mm) of slip. A grip between m g / (2 mu) and
m (g + a) / (2 mu) slides while the jaws accelerate and is caught once they cruise: it is
carried, a few millimetres down, so "carried" alone marks m g / (2 mu) (the slow-lift law,
``test_jaw_drive.py``), not the lift's formula; the slip limit marks the formula (a rigid
slider slides 1 mm at 0.986 of it).

dt 2 ms: the thresholds at 2 ms and at 0.5 ms agree within 0.4 % (``bench/friction_threshold.py
--dt 5e-4``). A 2 cm lift and a 0.2 s hold: near the threshold the fruit creeps about
0.4 mm per second of hold, so a 1 s hold (lift 5 cm) raises the threshold by 1 to 3 %.
"""
import pytest

from gripper_sim.configuration import load_config
from helpers import hold_threshold, lift_hold_minimum

#: the bisection's relative tolerance, fine against the 5 % check
TOLERANCE = 0.005


def threshold_within_5_percent(fruit, mu, lift, *overrides):
    config = load_config(fruit=fruit, overrides=[
        f'contact.jaw.static_friction={mu}', f'contact.jaw.kinetic_friction={mu}',
        'sim.dt=2e-3', *overrides])
    assert config['window.max_slip'] == 1e-3
    formula = lift_hold_minimum(config)
    threshold, below, trials = hold_threshold(config, 0.9 * formula, 1.1 * formula,
                                              lift=lift, tolerance=TOLERANCE)
    rows = [(round(t.force / formula, 4), t.outcome, round(t.slip_distance * 1e3, 3))
            for t in trials]
    assert threshold is not None, rows
    assert threshold - below <= TOLERANCE * threshold, rows
    assert 0.95 * formula <= below < threshold <= 1.05 * formula, rows


@pytest.mark.parametrize('mu', [0.3, 0.8])
@pytest.mark.parametrize('fruit', ['apple', 'plum'])
def test_the_hold_threshold_at_the_default_lift_is_the_lift_formula(fruit, mu):
    """Measured threshold / formula: apple 0.984 (mu 0.3), 0.988 (0.8); plum 0.959 at both."""
    assert load_config()['gripper.lift_acceleration'] == 0.5
    threshold_within_5_percent(fruit, mu, 0.02)


@pytest.mark.parametrize('mu', [0.3, 0.8])
@pytest.mark.parametrize('fruit', ['apple', 'plum'])
def test_the_hold_threshold_follows_the_lift_acceleration(fruit, mu):
    """At 2 m/s^2 (0.2 m/s, the same 0.1 s of acceleration) m g / (2 mu) is 17 % below
    the formula, so this tells the two apart (at the default lift a / g is 5 %). Measured
    threshold / formula: apple 0.99-1.00, plum 1.003 and 1.006 (the drive keeps 0.995 of
    the command while the table lets go of the soft plum)."""
    threshold_within_5_percent(fruit, mu, 0.04, 'gripper.lift_acceleration=2',
                               'gripper.lift_speed=0.2')
