"""Parameters of the ``gripper_sim`` node: declarations, descriptors, validation.

Every physics configuration key of ``gripper_sim.configuration.SCHEMA`` is a parameter
named ``physics.<key>`` (in a parameters file: ``physics: {fruit: {nodes: 96}}``),
declared with its unit, range and description. Structural keys are read-only (they
shape the model: set them at start-up with ``--ros-args -p`` or ``--params-file``);
the keys in ``DYNAMIC_PHYSICS_KEYS`` can change while the node runs. The node's own
parameters are in ``NODE_PARAMETERS``.

Start-up precedence: embedded defaults < ``fruit`` preset < ``config_file`` <
``physics.*`` parameter overrides. A value out of range, at start-up or later, is
rejected with a reason naming the parameter, its range and its unit; one of the wrong
type names the type it must be. An integer given for a floating-point parameter (``-p
real_time_factor:=1``, ``ros2 param set ... 1``) is taken as that number and stored as a
double. A nullable key (null: derived, or not used) left null is a parameter whose value
is not set (``PARAMETER_NOT_SET``, dynamically typed, so that it can be read). A
start-up override naming no parameter of the node is a warning naming the closest one.
"""
from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from gripper_sim import configuration
from gripper_sim.core.facade import DYNAMIC_KEYS
from gripper_sim.errors import ConfigError, ConfigWarning

PHYSICS_PREFIX = 'physics.'
# The publish interval is a whole number of steps, 1 / (publish_rate x dt): a rate
# closer to 0 than this has no such number (it overflows, or divides by 0).
MIN_PUBLISH_RATE = 0.001   # Hz

# Physics keys that may change while the node runs (the rest are read-only): the
# ones the core can change between steps.
DYNAMIC_PHYSICS_KEYS = DYNAMIC_KEYS


@dataclass(frozen=True)
class NodeParameter:
    """One parameter of the node itself (not a physics key)."""

    name: str
    default: Any
    unit: str
    description: str
    low: float | None = None
    high: float | None = None
    read_only: bool = False
    open_low: bool = False


NODE_PARAMETERS: tuple[NodeParameter, ...] = (
    NodeParameter('fruit', '', '-', "fruit preset name ('' = the default fruit, or the "
                  'one the config file names)', read_only=True),
    NodeParameter('config_file', '', '-', "YAML configuration file ('' = none); merged "
                  'after the fruit preset', read_only=True),
    NodeParameter('publish_rate', 100.0, 'Hz', 'state publishing rate, in sim time (at '
                  'least one message per 1000 s of sim time)', MIN_PUBLISH_RATE, 1000.0),
    NodeParameter('real_time_factor', 1.0, '', 'sim seconds per wall second; 0 = as fast '
                  'as possible', 0.0, 1000.0),
    NodeParameter('publish_clock', True, '-', 'publish /clock (sim time) at clock_rate'),
    NodeParameter('clock_rate', 1000.0, 'Hz', '/clock rate in sim time (at most every '
                  'physics step: the interval is a whole number of steps)', MIN_PUBLISH_RATE,
                  1e6),
    NodeParameter('marker_rate', 10.0, 'Hz', '~/markers rate in sim time (at most every '
                  'physics step)', MIN_PUBLISH_RATE, 1000.0),
    NodeParameter('max_effort', 10.0, 'N', 'GripperCommand: force limit used when a goal '
                  'has max_effort 0', 0.0, 1e5, open_low=True),
    NodeParameter('goal_tolerance', 0.001, 'm', 'GripperCommand: the goal is reached when '
                  '|gap - position| is below this', 0.0, 0.1, open_low=True),
    NodeParameter('allow_stalling', False, '-', 'GripperCommand: a stall ends the goal '
                  'with success (true) or abort (false)'),
    NodeParameter('stall_velocity_threshold', 0.001, 'm/s', 'GripperCommand: a stall '
                  'is a mean gap rate below this over stall_timeout', 0.0, 1.0,
                  open_low=True),
    NodeParameter('stall_timeout', 1.0, 's', 'GripperCommand: stall window, sim time',
                  0.0, 60.0, open_low=True),
    NodeParameter('record_path', '', '-', "bag folder to record every physics step to "
                  "(NAME/NAME_0.mcap + metadata.yaml; one file if it ends in .mcap; "
                  "'' = not recording); setting it starts recording there (an existing "
                  "file or folder is refused), '' stops; ~/record also sets it"),
    NodeParameter('frame_prefix', '', '-', "prepended to every TF frame id the node "
                  "publishes (e.g. 'gripper1/'); 'world' stays shared", read_only=True),
    NodeParameter('foxglove_port', 8765, '-', 'TCP port of the Foxglove live view '
                  '(WebSocket); 0 = off', 0, 65535, read_only=True),
    NodeParameter('foxglove_address', '127.0.0.1', '-', 'address the Foxglove live view '
                  'listens on', read_only=True),
)


def _range_text(low, high, unit, open_low=False) -> str:
    unit = f' {unit}' if unit not in ('', '-') else ''
    lower = '(' if open_low else '['
    return f'{lower}{low}, {high}]{unit}'


def _descriptor(name: str, value: Any, description: str, unit: str, low=None, high=None,
                read_only=False, open_low=False) -> ParameterDescriptor:
    text = description
    if unit not in ('', '-'):
        text += f' [{unit}]'
    if low is not None and high is not None:
        text += f'; range {_range_text(low, high, unit, open_low)}'
    descriptor = ParameterDescriptor(name=name, description=text, read_only=read_only)
    if isinstance(value, bool) or low is None or high is None:
        return descriptor
    if isinstance(value, int):
        descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high),
                                                 step=1)]
    else:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(low), to_value=float(high), step=0.0)]
    return descriptor


_KIND_TYPES = {
    'float': Parameter.Type.DOUBLE,
    'int': Parameter.Type.INTEGER,
    'bool': Parameter.Type.BOOL,
    'str': Parameter.Type.STRING,
}
#: a parameter type as a message asks for it
_TYPE_NAMES = {
    Parameter.Type.DOUBLE: 'a floating-point number',
    Parameter.Type.INTEGER: 'an integer',
    Parameter.Type.BOOL: 'true or false',
    Parameter.Type.STRING: 'a string',
}
# rclpy's QoS overrides: parameters of publishers made with QoSOverridingOptions, which
# rclpy declares with them; not a misspelt parameter of this node.
QOS_OVERRIDES_PREFIX = 'qos_overrides.'


@dataclass(frozen=True)
class ValueType:
    """The type a parameter's values must have, and a value of it a message shows."""

    type_: Parameter.Type
    example: Any


def _not_set_meaning(description: str) -> str:
    """A nullable key's description for its parameter: the schema's 'null = X' (what
    the model does without a value) reads 'not set = X'."""
    if 'null = ' in description:
        return description.replace('null = ', 'not set = ')
    return description + ' (not set where it does not apply)'


def physics_descriptor(key: str) -> ParameterDescriptor:
    """Descriptor of parameter ``physics.<key>`` from the configuration schema.

    A nullable key's parameter is dynamically typed: rclpy can then report it while it
    has no value (``PARAMETER_NOT_SET``); ``SimParameters`` checks its type instead."""
    spec = configuration.SCHEMA[key]
    description = spec.description
    if spec.nullable:
        description = _not_set_meaning(description)
    if spec.choices:
        description += f" (one of: {', '.join(spec.choices)})"
    sample = {'float': 0.0, 'int': 0, 'bool': False, 'str': ''}[spec.kind]
    descriptor = _descriptor(PHYSICS_PREFIX + key, sample, description, spec.unit, spec.low,
                             spec.high, read_only=key not in DYNAMIC_PHYSICS_KEYS,
                             open_low=spec.open_low)
    if spec.nullable:
        descriptor.description += f'; {_TYPE_NAMES[_KIND_TYPES[spec.kind]]}, or not set'
        descriptor.dynamic_typing = True
    return descriptor


def _as_type(parameter: Parameter, expected: Parameter.Type | None) -> Parameter:
    """``parameter``, an integer given for a floating-point parameter as that double."""
    if expected == Parameter.Type.DOUBLE and parameter.type_ == Parameter.Type.INTEGER:
        return Parameter(parameter.name, Parameter.Type.DOUBLE, float(parameter.value))
    return parameter


def _type_problem(parameter: Parameter, expected: ValueType) -> str | None:
    """Why ``parameter`` (after ``_as_type``) is not of the ``expected`` type, with how
    to write such a value; None if it is."""
    given = parameter.value
    if parameter.type_ == expected.type_:
        return None
    wanted = _TYPE_NAMES[expected.type_]
    how = f', e.g. {expected.example!r}'
    if (expected.type_ == Parameter.Type.INTEGER and parameter.type_ == Parameter.Type.DOUBLE
            and math.isfinite(given) and given.is_integer()):
        how = f': write {int(given)}, not {given}'
    elif expected.type_ == Parameter.Type.STRING:
        how = f": quote it ('{given}')"
    elif expected.type_ == Parameter.Type.BOOL:
        how = ''
    elif (expected.type_ == Parameter.Type.DOUBLE and parameter.type_ == Parameter.Type.STRING
          and _reads_as_number(given)):
        # rcl reads a number it cannot hold as a double (below 2.2e-308 or above 1.8e308)
        # as text
        how = ' in the double range (it was read as text)'
    return f"parameter '{parameter.name}' = {given!r} is invalid: it must be {wanted}{how}"


def _reads_as_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _physics_names(text: str) -> str:
    """A configuration error message in terms of ``physics.*`` parameter names."""
    text = text.replace('config key ', 'parameter ')
    for key in configuration.SCHEMA:
        text = text.replace(f"'{key}'", f"'{PHYSICS_PREFIX}{key}'")
    return text


def _node_range_problem(name: str, value: Any) -> str | None:
    """Open lower bounds, which a ParameterDescriptor range cannot express."""
    for spec in NODE_PARAMETERS:
        if spec.name == name and spec.open_low and isinstance(value, (int, float)) \
                and not isinstance(value, bool) and value <= spec.low:
            return (f"parameter '{name}' = {value} is out of range: it must be in "
                    f'{_range_text(spec.low, spec.high, spec.unit, True)}')
    return None


def _finite_problem(name: str, value: Any) -> str | None:
    if isinstance(value, float) and not math.isfinite(value):
        return f"parameter '{name}' must be finite, got {value}"
    return None


def _physics_type(key: str, default: Any) -> ValueType:
    """The type of parameter ``physics.<key>``; ``default``, or its range's upper end,
    the example."""
    spec = configuration.SCHEMA[key]
    example = default
    if example is None:
        example = (spec.high if spec.high is not None
                   else {'float': 1.0, 'int': 1, 'bool': False, 'str': ''}[spec.kind])
    if spec.kind == 'float':
        example = float(example)
    return ValueType(_KIND_TYPES[spec.kind], example)


def _defaults_of(fruit: str | None, config_file: str | None,
                 overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The configuration before the node's parameters apply (the physics parameters'
    defaults); its warnings come once, with the final configuration's."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', ConfigWarning)
        return configuration.load_config(fruit=fruit, config_file=config_file,
                                         overrides=overrides or {})


class SimParameters:
    """Declares the node's parameters, builds the physics configuration, validates changes.

    Args:
        node: the node to declare on.
        fruit, config_file: values that take precedence over the parameters of the same
            name (the ``gripper-sim node --fruit/--config`` options).

    Attributes:
        config: the validated flat physics configuration in use.

    Raises:
        ConfigError: the fruit, file or a ``physics.*`` override is invalid (the
            message names the key, its range and unit).
    """

    def __init__(self, node: Node, fruit: str | None = None, config_file: str | None = None):
        self._node = node
        self._listeners: list[Callable[[dict[str, Any]], None]] = []
        self._types: dict[str, ValueType] = {}
        for spec in NODE_PARAMETERS:
            self._declare_checked(spec.name, spec.default, ValueType(
                Parameter.Type.from_parameter_value(spec.default), spec.default),
                _descriptor(spec.name, spec.default, spec.description, spec.unit, spec.low,
                            spec.high, spec.read_only, spec.open_low),
                spec.unit, spec.low, spec.high, spec.open_low)
        fruit = fruit or node.get_parameter('fruit').value or None
        config_file = config_file or node.get_parameter('config_file').value or None
        base = _defaults_of(fruit, config_file)
        overrides: dict[str, Any] = {}
        for key, spec in configuration.SCHEMA.items():
            default = base[key]
            value = self._declare_checked(
                PHYSICS_PREFIX + key, default, _physics_type(key, default),
                physics_descriptor(key), spec.unit, spec.low, spec.high, spec.open_low)
            if value is not None and value != default:
                overrides[key] = value
                if key == 'dimension':
                    # the other keys' defaults follow the dimension (e.g. 3D's sim.dt)
                    base = _defaults_of(fruit, config_file, {'dimension': value})
        self._warn_unknown_overrides()
        with warnings.catch_warnings(record=True) as caught:   # once, in the node's log
            warnings.simplefilter('always', ConfigWarning)
            self.config = configuration.load_config(fruit=fruit, config_file=config_file,
                                                    overrides=overrides)
        for warning in caught:
            node.get_logger().warning(str(warning.message))
        self.fruit = str(self.config['fruit.name'])
        node.add_pre_set_parameters_callback(self._integers_as_doubles)
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._applied)

    def _declare_checked(self, name, default, expected: ValueType, descriptor, unit, low,
                         high, open_low=False):
        """Declare ``name`` with its start-up override, else ``default``; its value.

        Raises:
            ConfigError: the override is of the wrong type (the message names the type
                and how to write it) or out of range.
        """
        value = default
        given = self._start_up_overrides().get(name)
        if given is not None:
            given = _as_type(given, expected.type_)
            problem = _type_problem(given, expected)
            if problem and not (descriptor.dynamic_typing
                                and given.type_ == Parameter.Type.NOT_SET):
                raise ConfigError(problem)
            value = given.value
        try:
            parameter = self._node.declare_parameter(name, value, descriptor,
                                                     ignore_override=True)
        except InvalidParameterValueException as err:   # out of the descriptor's range
            bounds = (f'out of range: it must be in {_range_text(low, high, unit, open_low)}'
                      if low is not None and high is not None else f'invalid ({err})')
            raise ConfigError(f"parameter '{name}' = {value!r} is {bounds}") from err
        self._types[name] = expected
        value = parameter.value
        problem = _finite_problem(name, value) or _node_range_problem(name, value)
        if problem:
            raise ConfigError(problem)
        return value

    def _start_up_overrides(self) -> Mapping[str, Parameter]:
        """rclpy's store of the node's start-up overrides (``-p``, parameters files, the
        ``parameter_overrides`` argument), declared names or not: rclpy has no public
        getter of them."""
        return getattr(self._node, '_parameter_overrides', {})

    def _warn_unknown_overrides(self) -> None:
        """Log a warning for each start-up override naming no parameter of the node (a
        misspelt name would otherwise be ignored without a word); the node runs on, as
        a parameters file for ``/**`` may serve other nodes too."""
        node = self._node
        for name in sorted(self._start_up_overrides()):
            if node.has_parameter(name) or name.startswith(QOS_OVERRIDES_PREFIX):
                continue   # declared: this node's, or rclpy's own (use_sim_time, ...)
            close = difflib.get_close_matches(name, list(self._types), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ''
            node.get_logger().warning(f"parameter '{name}' given at start-up is ignored: "
                                      f'this node has no such parameter{hint}')

    def _integers_as_doubles(self, parameters: list[Parameter]) -> list[Parameter]:
        """rclpy pre-set callback: an integer set on a floating-point parameter (``ros2
        param set /gripper_sim real_time_factor 1``) is set as that double."""
        return [_as_type(parameter, getattr(self._types.get(parameter.name), 'type_', None))
                for parameter in parameters]

    def get(self, name: str) -> Any:
        """Current value of node parameter ``name``."""
        return self._node.get_parameter(name).value

    def on_change(self, listener: Callable[[dict[str, Any]], None]) -> None:
        """Call ``listener({name: value})`` after accepted parameter changes."""
        self._listeners.append(listener)

    def _validate(self, parameters: list[Parameter]) -> SetParametersResult:
        candidate = dict(self.config)
        for parameter in parameters:
            name, value = parameter.name, parameter.value
            problem = _finite_problem(name, value) or _node_range_problem(name, value)
            if problem:
                return self._reject(problem)
            expected = self._types.get(name)
            if expected is not None and parameter.type_ != Parameter.Type.NOT_SET:
                problem = _type_problem(parameter, expected)   # a dynamically typed one
                if problem:
                    return self._reject(problem)
            if name.startswith(PHYSICS_PREFIX):
                key = name[len(PHYSICS_PREFIX):]
                if key in configuration.SCHEMA:
                    if parameter.type_ == Parameter.Type.NOT_SET:
                        return self._reject(f"parameter '{name}' cannot be unset")
                    candidate[key] = value
        try:
            configuration.validate(candidate)
        except ConfigError as err:
            return self._reject(_physics_names(str(err)))
        return SetParametersResult(successful=True)

    def _reject(self, reason: str) -> SetParametersResult:
        self._node.get_logger().warning(f'parameter change rejected: {reason}')
        return SetParametersResult(successful=False, reason=reason)

    def _applied(self, parameters: list[Parameter]) -> None:
        changes: dict[str, Any] = {}
        physics: dict[str, Any] = {}
        for parameter in parameters:
            if parameter.name.startswith(PHYSICS_PREFIX):
                key = parameter.name[len(PHYSICS_PREFIX):]
                if key in configuration.SCHEMA:
                    physics[key] = parameter.value
            changes[parameter.name] = parameter.value
        if physics:
            self.config = self.config.replaced(physics)
        for listener in self._listeners:
            listener(changes)


def physics_changes(changes: Mapping[str, Any]) -> dict[str, Any]:
    """The ``physics.*`` entries of ``changes`` as ``{config key: value}``."""
    return {name[len(PHYSICS_PREFIX):]: value for name, value in changes.items()
            if name.startswith(PHYSICS_PREFIX)}
