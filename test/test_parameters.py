"""The validated configuration is typed and frozen; the schema names the run-time keys."""
import copy
import pickle

import pytest

from gripper_sim import configuration
from gripper_sim.configuration import RUNTIME_KEYS, SCHEMA, Parameters, load_config
from gripper_sim.core.facade import DYNAMIC_KEYS
from gripper_sim.errors import ConfigError
from gripper_sim.workflows.factory import make_simulation


def test_a_loaded_configuration_is_frozen_and_typed():
    config = load_config('apple', overrides=['sim.dt=1e-3'])
    assert isinstance(config, Parameters)
    assert isinstance(config['sim.dt'], float) and isinstance(config['dimension'], int)
    for change in (lambda: config.__setitem__('sim.dt', 2e-3),
                   lambda: config.update({'sim.dt': 2e-3}),
                   lambda: config.pop('sim.dt'), lambda: config.clear(),
                   lambda: config.setdefault('x', 1)):
        with pytest.raises(TypeError, match='frozen'):
            change()
    with pytest.raises(TypeError):
        del config['sim.dt']
    assert config['sim.dt'] == 1e-3
    editable = dict(config)
    editable['sim.dt'] = 2e-3
    assert config['sim.dt'] == 1e-3


def test_replaced_validates_and_copies_survive_pickling():
    config = load_config('apple')
    faster = config.replaced({'gripper.close_speed': 0.05})
    assert faster['gripper.close_speed'] == 0.05 and config['gripper.close_speed'] == 0.02
    assert isinstance(faster, Parameters)
    with pytest.raises(ConfigError, match="'gripper.close_speed'"):
        config.replaced({'gripper.close_speed': -1.0})
    with pytest.raises(ConfigError, match="unknown config key 'gripper.closespeed'"):
        config.replaced({'gripper.closespeed': 0.05})
    for clone in (pickle.loads(pickle.dumps(config)), copy.copy(config), copy.deepcopy(config)):
        assert isinstance(clone, Parameters) and clone == config


def test_the_runtime_keys_are_the_schema_s_and_only_they_change_a_simulation():
    assert RUNTIME_KEYS == DYNAMIC_KEYS
    assert set(RUNTIME_KEYS) == {key for key, spec in SCHEMA.items() if spec.runtime}
    assert 'contact.jaw.static_friction' in RUNTIME_KEYS and 'sim.dt' not in RUNTIME_KEYS
    sim = make_simulation(load_config('apple'))
    assert isinstance(sim.config, Parameters)
    sim.set_parameter('contact.jaw.static_friction', 0.9)
    assert sim.config['contact.jaw.static_friction'] == 0.9
    with pytest.raises(ConfigError, match="'sim.dt' cannot change while running"):
        sim.set_parameter('sim.dt', 2e-3)
    with pytest.raises(ConfigError, match='kinetic_friction'):
        sim.set_parameter('contact.jaw.static_friction', 0.1)   # below mu_k 0.4
    assert sim.config['contact.jaw.static_friction'] == 0.9
    assert configuration.validate(sim.config) == sim.config
