"""Input handling of the configuration and the offline verbs: files that are not UTF-8 or
not valid YAML, keys given twice, jaws that would start inside the fruit, output files
that cannot be written, and a ``pick --hold`` longer than the old fixed time limit.

Every bad input is one ``error: ...`` line and exit 2, found before a simulation runs.
"""
import warnings

import pytest

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config, read_yaml
from gripper_sim.errors import ConfigError, ConfigWarning
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import GraspSequence, evaluate, run_grasp


def one_error_line(capsys) -> str:
    """The verb's stderr, checked to be a single ``error: ...`` line; its text."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('error: '), err
    return lines[0]


def no_simulation(monkeypatch):
    """Make any simulation step fail the test: the error must come before one."""
    def refuse(*args, **kwargs):
        raise AssertionError('the simulation ran before the input was checked')
    for name in ('gripper_sim.core.simulation.Simulation.step',
                 'gripper_sim.core.simulation.Simulation.advance',
                 'gripper_sim.workflows.window.grasp_window'):
        monkeypatch.setattr(name, refuse)


# ------------------------------------------------------------------ item 1: not UTF-8
@pytest.fixture
def not_utf8(tmp_path):
    path = tmp_path / 'g.yaml'
    path.write_bytes(b'\xff\xfe')
    return path


@pytest.mark.parametrize('verb', [
    ['squeeze', '--to-force', '5', '--config', '{file}'],
    ['squeeze', '--to-force', '5', '--fruit', '{file}'],
    ['run', '{file}'],
    ['study', '{file}'],
])
def test_a_file_that_is_not_utf8_is_one_error_line(verb, not_utf8, capsys, monkeypatch):
    no_simulation(monkeypatch)
    assert main([arg.format(file=not_utf8) for arg in verb]) == 2
    line = one_error_line(capsys)
    assert 'not UTF-8' in line and 'g.yaml' in line and '0xff' in line


# ------------------------------------------------------- item 7: malformed YAML, one line
def test_malformed_yaml_is_one_line_with_its_line_and_column(tmp_path, capsys):
    path = tmp_path / 'bad.yaml'
    path.write_text('sim: [1, 2\nfruit: apple\n')
    assert main(['squeeze', '--to-force', '5', '--config', str(path)]) == 2
    line = one_error_line(capsys)
    assert 'not valid YAML' in line and 'line 2, column' in line


def test_a_control_character_is_one_line(tmp_path):
    path = tmp_path / 'ctl.yaml'
    path.write_text('sim:\n  dt: \x01\n')
    with pytest.raises(ConfigError, match=r'#x0001') as caught:
        read_yaml(path)
    assert '\n' not in str(caught.value)


# ------------------------------------------------------------- item 6: a key given twice
@pytest.mark.parametrize('text,key', [
    ('sim.dt: 0.001\nsim: {dt: 0.002}\n', 'sim.dt'),
    ('sim: {dt: 0.002}\nsim.dt: 0.001\n', 'sim.dt'),
    ('fruit: apple\nfruit: plum\n', 'fruit'),
    ('sim:\n  dt: 0.001\n  dt: 0.002\n', 'dt'),
    ('sim:\n  dt: 0.001\nsim:\n  max_halvings: 3\n', 'sim'),
])
def test_a_key_given_twice_in_one_file_is_an_error_naming_it(tmp_path, text, key):
    path = tmp_path / 'twice.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError, match=f"'{key}' is given twice") as caught:
        load_config(config_file=path)
    assert '\n' not in str(caught.value)


def test_a_merged_mapping_may_still_be_overridden(tmp_path):
    """YAML's merge key (``<<: *base``) is no key given twice: a key beside it wins."""
    path = tmp_path / 'merge.yaml'
    path.write_text('a: &d {dt: 0.001, max_halvings: 3}\nb:\n  <<: *d\n  dt: 0.002\n')
    assert read_yaml(path)['b'] == {'dt': 0.002, 'max_halvings': 3}


# ------------------------------------------- items 2 and 3: jaws that start in the fruit
@pytest.mark.parametrize('overrides', [
    ['fruit.shape.diameter=0.3'],
    ['fruit.shape.diameter=0.3', 'dimension=3'],
    ['fruit.shape.type=ellipse', 'fruit.model=solid', 'fruit.shape.diameter=0.25',
     'fruit.shape.height=0.05'],
])
def test_a_fruit_wider_than_the_jaws_open_is_refused_up_front(overrides):
    with pytest.raises(ConfigError, match=r"gripper\.max_gap' = 200 mm") as caught:
        make_simulation(load_config(overrides=overrides))
    assert 'does not fit between the jaws' in str(caught.value)


def test_a_fruit_that_fits_starts_at_most_at_the_largest_gap():
    sim = make_simulation(load_config(overrides=['fruit.shape.diameter=0.195']))
    assert sim.initial_gap == pytest.approx(0.2)


@pytest.mark.parametrize('overrides', [
    ['gripper.initial_gap=0.01'],
    ['gripper.initial_gap=0.06', 'gripper.finger.pad.enabled=true'],
    ['gripper.initial_gap=0.06', 'gripper.finger.type=vgroove'],
    ['gripper.initial_gap=0.01', 'dimension=3'],
])
def test_a_starting_gap_inside_the_fruit_is_refused(overrides):
    with pytest.raises(ConfigError, match=r"'gripper\.initial_gap' = .* inside the fruit: "
                                          r'the fingers touch it at a gap of 63'):
        make_simulation(load_config(overrides=overrides))


@pytest.mark.parametrize('finger', ['fin_ray', 'solid_pad'])
def test_soft_fingers_touch_the_fruit_at_their_own_gap(finger):
    """A gap wider than the fruit but inside the soft fingers' reach is refused too."""
    with pytest.raises(ConfigError, match='does not fit between'):
        make_simulation(load_config(overrides=[f'gripper.finger.type={finger}',
                                               'gripper.initial_gap=0.07']))


def test_a_starting_gap_at_the_fruit_s_width_touches_it():
    sim = make_simulation(load_config(overrides=['gripper.initial_gap=0.0635']))
    assert sim.initial_gap == sim.touching_gap


@pytest.mark.parametrize('verb', [
    ['squeeze', '--to-force', '10', '--set', 'fruit.shape.diameter=0.3'],
    ['squeeze', '--to-force', '5', '--set', 'gripper.initial_gap=0.01'],
    ['pick', '--force', '3', '--set', 'gripper.initial_gap=0.01'],
    ['pick', '--force', '3', '--set', 'fruit.shape.diameter=0.3'],
    ['run', 'pick_and_place', '--set', 'gripper.initial_gap=0.01'],
])
def test_the_verbs_refuse_jaws_in_the_fruit_before_they_run(verb, capsys, monkeypatch):
    no_simulation(monkeypatch)
    assert main(verb) == 2
    assert 'gripper.' in one_error_line(capsys)


# ------------------------------------------------------------ item 4: a long pick hold
def test_the_time_limit_of_a_pick_covers_its_hold():
    sim = make_simulation(load_config())
    sequence = GraspSequence(sim, 3.0, lift_height=0.05, hold_time=1000.0)
    assert sequence.time_needed() > 1000.0 + sequence.closing_deadline


def test_a_grasp_stopped_at_its_time_limit_says_so():
    sim = make_simulation(load_config())
    summary = run_grasp(sim, GraspSequence(sim, 3.0, hold_time=1.0), time_limit=0.01)
    assert summary['outcome'] == 'running'
    assert 'time limit' in summary['message'] and 'closing' in summary['message']


def test_evaluate_uses_the_time_the_machine_needs():
    class Waiting:
        phase = 'waiting'
        done = False

        def update(self, result):
            return self.phase

        def summary(self):
            return dict(outcome='running', message='')

        def time_needed(self):
            return 0.005

    sim = make_simulation(load_config())
    evaluation = evaluate(sim, Waiting(), 1.0)
    assert evaluation.sim_time == pytest.approx(0.005, abs=sim.dt)
    assert 'time limit (0.005 s simulated) while waiting' in evaluation.message


# ------------------------------------------------------- item 5: outputs checked up front
@pytest.mark.parametrize('verb', [
    ['window', '--html', '{tmp}/nodir/w.html'],
    ['squeeze', '--to-force', '5', '--html', '{tmp}/nodir/x.html'],
    ['squeeze', '--to-force', '5', '--html', '{tmp}'],
    ['pick', '--force', '3', '--html', '{tmp}/nodir/x.html'],
    ['run', 'pick_and_place', '--html', '{tmp}/nodir/x.html'],
    ['run', 'pick_and_place', '--out', '{tmp}/nodir/x.mcap'],
    ['pick', '--force', '3', '--out', '{tmp}/taken.mcap'],
])
def test_every_output_is_checked_before_the_run(verb, tmp_path, capsys, monkeypatch):
    (tmp_path / 'taken.mcap').write_bytes(b'')
    no_simulation(monkeypatch)
    assert main([arg.format(tmp=tmp_path) for arg in verb]) == 2
    line = one_error_line(capsys)
    assert line.startswith('error: cannot write --')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['taken.mcap']


def test_an_existing_report_may_be_replaced_and_is_not_touched_by_the_check(tmp_path):
    from gripper_sim.cli.offline import check_output_file
    report = tmp_path / 'r.html'
    report.write_text('old')
    check_output_file(str(report), '--html', replace=True)
    assert report.read_text() == 'old'
    check_output_file(str(tmp_path / 'new.html'), '--html', replace=True)
    assert not (tmp_path / 'new.html').exists()


# ----------------------------------------------------- soft-finger audit: keys and names
@pytest.mark.parametrize('finger, overrides, warned', [
    ('fin_ray', ['gripper.finger.fin_ray.rib_ends=[[0.01,0.02],[0.03,0.04]]',
                 'gripper.finger.fin_ray.rib_count=3'],
     "'gripper.finger.fin_ray.rib_count' has no effect: 'gripper.finger.fin_ray.rib_ends' "
     'places the ribs'),
    ('flat', ['contact.ipc.dhat=1e-5'],
     "'contact.ipc.dhat' has no effect: the contact with the rigid fingers is the "
     'modified mass method'),
    ('solid_pad', ['gripper.finger.pad.thickness=0.002'],
     "'gripper.finger.pad.thickness' has no effect: the solid_pad finger is itself soft"),
])
def test_keys_without_effect_on_soft_fingers_and_rigid_contact_are_warned(
        finger, overrides, warned):
    with pytest.warns(ConfigWarning) as caught:
        load_config(finger=finger, overrides=overrides)
    assert any(warned in str(w.message) for w in caught), [str(w.message) for w in caught]


def test_the_barrier_keys_count_with_the_barrier():
    with warnings.catch_warnings():
        warnings.simplefilter('error', ConfigWarning)
        load_config(overrides=['contact.model=ipc', 'contact.ipc.dhat=1e-5'])
        load_config(finger='fin_ray', overrides=['contact.ipc.stiffness=1'])


@pytest.mark.parametrize('overrides, name', [
    (['gripper.finger.type=fin_ray'], 'fin_ray'),
    (['gripper.finger.type=solid_pad'], 'solid_pad'),
    (['gripper.finger.type=fin_ray', 'gripper.finger.name=my_ray'], 'my_ray'),
    (['finger=soft_pad'], 'soft_pad'),
])
def test_the_finger_shown_in_outputs_is_the_type_chosen_by_key(overrides, name):
    assert load_config(overrides=overrides)['gripper.finger.name'] == name

