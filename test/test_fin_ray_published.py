"""Our Fin Ray against a published case (``bench/fin_ray_published.py``: the thesis
repository github.com/zeyang23/Fin-ray, Experiments/test_05_20_plot.m, a steel-strip Fin
Ray pressed onto a rigid cylinder), and the ``rib_ends`` configuration it uses."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))

import fin_ray_published as published  # noqa: E402
from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.errors import ConfigError  # noqa: E402
from gripper_sim.geometry.fin_ray import FinRayGeometry, rib_points  # noqa: E402

PREFIX = 'gripper.finger.fin_ray.'


def _errors(radius, **options):
    """Our |F| / measured |F| - 1 at delta 5..30 mm, and the run (``published.run``'s
    options)."""
    result, _ = published.run(radius, element_length=2e-3, **options)
    sensor = published.MEASURED[radius][0]
    rows = []
    for delta, measured in zip(published.DELTAS, sensor):
        i = int(np.argmin(np.abs(result.delta - delta)))
        rows.append(math.hypot(*result.force[i]) / math.hypot(*measured) - 1.0)
    return np.array(rows), result


def _tangential_misfit(result, radius):
    """N, the root mean square of our tangential force's magnitude (along the front beam)
    less the sensor's, over delta 5..30 mm."""
    sensor = published.MEASURED[radius][0]
    misfit = [abs(result.force[int(np.argmin(np.abs(result.delta - delta))), 1]) - ft
              for delta, (ft, _fn) in zip(published.DELTAS, sensor)]
    return float(np.sqrt(np.mean(np.square(misfit))))


@pytest.fixture(scope='module')
def r30():
    return _errors(0.030)


@pytest.fixture(scope='module')
def r20():
    return _errors(0.020)


def test_the_base_holds_what_presses_the_cylinder(r20):
    _, result = r20
    assert np.allclose(result.reaction, result.force[-1], rtol=1e-3, atol=1e-3)
    push = result.force[:, 0]
    assert np.all(np.diff(push) > 0), 'the force rises with the travel'


def test_30_mm_cylinder_within_15_percent_up_to_15_mm(r30):
    errors, _ = r30
    assert np.all(np.abs(errors[:3]) < 0.15), errors


def test_30_mm_cylinder_within_25_percent_to_30_mm(r30):
    errors, _ = r30
    assert np.all(np.abs(errors) < 0.25), errors


def test_20_mm_cylinder_as_reported(r20):
    """The figures the README gives: 20-29 % below the measurement, outside the issue's
    15 % (with the source model's undocumented E scaling, or its 22.5 mm radius, 12-22 %
    below)."""
    errors, _ = r20
    assert np.all((-0.32 < errors) & (errors < -0.17)), errors


@pytest.fixture(scope='module')
def plates_with_friction():
    """Both cylinders, the strips bent as plates, the contact with mu = 0.2."""
    return {radius: _errors(radius, plate=True, friction=0.2) for radius in (0.02, 0.03)}


def test_plates_with_friction_are_within_15_percent_at_every_point(plates_with_friction):
    """The README's figures: -14 to +9 % at delta 5..30 mm on both cylinders."""
    for radius, (errors, _) in plates_with_friction.items():
        assert np.all(np.abs(errors) < 0.15), (radius, errors)


def test_friction_fits_the_sensors_tangential_force_better(plates_with_friction, r20, r30):
    """mu = 0.2 is read off the tangential components (module README): frictionless,
    ours misses them by 0.3 N rms; with mu = 0.2, by about 0.25 N."""
    with_friction = np.mean([_tangential_misfit(result, radius)
                             for radius, (_, result) in plates_with_friction.items()])
    frictionless = np.mean([_tangential_misfit(r20[1], 0.02), _tangential_misfit(r30[1], 0.03)])
    assert with_friction < 0.8 * frictionless, (with_friction, frictionless)


def test_with_friction_the_base_still_holds_what_presses_the_cylinder(plates_with_friction):
    _, result = plates_with_friction[0.02]
    assert np.allclose(result.reaction, result.force[-1], rtol=1e-3, atol=1e-3)
    pressed = result.delta >= published.DELTAS[0] - 1e-9
    assert np.all(result.force[pressed, 1] > 0), 'friction turns the tangential force round'


@pytest.mark.parametrize('value', ['-0.1', 'nan', 'inf'])
def test_a_bad_friction_coefficient_is_refused(value, capsys):
    with pytest.raises(SystemExit) as stop:
        published.main(['--friction', value])
    assert stop.value.code == 2
    assert 'must be a number >= 0' in capsys.readouterr().err


@pytest.fixture(scope='module')
def source_model_20():
    return published.run(0.0225, element_length=2e-3, e_scaling=True, source_ribs=True)


def test_with_the_source_models_inputs_ours_reproduces_its_saved_run(source_model_20):
    """Two independent models of the same finger (its 50 pseudo-rigid segments per strip
    and three fitted point contacts; our rods and continuous barrier contact) given the
    same inputs: the sum of the contact forces within 3 % at every delta."""
    result, _ = source_model_20
    saved = np.array(published.SAVED_RUNS[0.0225])
    ours = np.array([result.pressing[int(np.argmin(np.abs(result.delta - d)))]
                     for d in published.DELTAS])
    assert np.all(np.abs(ours / saved - 1.0) < 0.03), ours / saved - 1.0


def test_the_sum_of_contact_magnitudes_bounds_the_net_force(source_model_20):
    result, _ = source_model_20
    net = np.hypot(*result.force.T)
    assert np.all(net <= result.pressing * (1 + 1e-12))
    assert np.all(net >= 0.98 * result.pressing), 'a contact arc of a few degrees'


def test_the_source_models_crossbeams_are_nearer_the_base_and_prestressed(source_model_20):
    snapped = np.array(published.source_rib_ends())
    nominal = np.array(published.RIB_ENDS)
    segments = np.array([published.BACK, published.FRONT]) / published.SOURCE_SEGMENTS
    assert np.all((snapped <= nominal) & (snapped > nominal - segments))
    _, body = source_model_20
    assert len(body.rod_rest_lengths) == len(body.rod_edges)
    drawn = np.linalg.norm(body.rest_positions[body.rod_edges[:, 1]]
                           - body.rest_positions[body.rod_edges[:, 0]], axis=1)
    shorter = body.rod_rest_lengths < drawn * (1 - 1e-9)
    # the ribs' own edges pull: their rest lengths sum to the nominal crossbeam lengths
    lengths = [published.crossbeam_length(*pair) for pair in published.RIB_ENDS]
    assert body.rod_rest_lengths[shorter].sum() == pytest.approx(sum(lengths), rel=1e-9)
    assert np.all(body.rod_rest_lengths[~shorter] == pytest.approx(drawn[~shorter]))


def _config(ends, **more):
    overrides = ['gripper.finger.type=fin_ray', f'{PREFIX}rib_ends={json.dumps(ends)}']
    overrides += [f'{PREFIX}{k}={v}' for k, v in more.items()]
    return load_config(overrides=overrides)


def test_rib_ends_place_the_ribs_and_set_their_count():
    config = _config([[0.02, 0.03], [0.045, 0.05]])
    geometry = FinRayGeometry.from_config(config, 0.02)
    assert geometry.rib_count == 2
    backs, fronts = rib_points(geometry)
    corner = np.array([0.0, 0.03])
    assert np.allclose(np.linalg.norm(backs - corner, axis=1), [0.02, 0.045])
    front_corner = np.array([geometry.base_width, 0.03])
    assert np.allclose(np.linalg.norm(fronts - front_corner, axis=1), [0.03, 0.05])


def test_null_rib_ends_keep_the_spacing_rule():
    config = load_config(overrides=['gripper.finger.type=fin_ray'])
    geometry = FinRayGeometry.from_config(config, 0.02)
    assert geometry.rib_ends is None and len(rib_points(geometry)[0]) == config[
        PREFIX + 'rib_count']


@pytest.mark.parametrize('ends, words', [
    ([[0.02, 0.03], [0.5, 0.05]], 'rib 2 of 2 is off the back beam'),
    ([[0.02, -0.01]], 'rib 1 of 1 is off the front beam'),
    ([[0.02, 0.05], [0.045, 0.03]], 'ribs 1 and 2 cross'),
    ([[0.02, 0.03], [0.0204, 0.05]], 'not more than a rib thickness'),
    ('not a list', 'must be a list of [back, front] number pairs'),
    ([[0.02, 0.03], [0.02, 0.03]], 'not more than a rib thickness'),
])
def test_bad_rib_ends_are_refused_clearly(ends, words):
    with pytest.raises(ConfigError, match='rib_ends') as error:
        _config(ends)
    assert words in str(error.value)


def test_an_unknown_rib_joint_is_refused():
    with pytest.raises(ConfigError, match='rib_joint'):
        load_config(overrides=['gripper.finger.type=fin_ray', f'{PREFIX}rib_joint=glued'])
