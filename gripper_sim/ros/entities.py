"""The entity services of simulation_interfaces over the node's one simulation:
``get_entities``, ``get_entity_state``, ``get_spawnables``, ``spawn_entity`` and
``delete_entity``, named in the node's namespace.

Entities: the fruit (a dynamic object; ``fruit`` at start-up), ``left_jaw`` and
``right_jaw`` (the robot) and, when the world has one, ``table`` (a static object). There
is always exactly one fruit: ``spawn_entity`` replaces it by another preset, under the
name the standard gives it (the request's, else the preset's ``fruit.name``; a taken or
missing one is refused unless ``allow_renaming``); the new fruit starts at rest on the
table, as after a reset. A reset whose scope includes ``SCOPE_SPAWNED`` brings the
start-up fruit back (``restore_startup_fruit``). ``delete_entity`` refuses every entity,
the fruit included (a gripper simulation without a fruit has nothing to simulate).

``filters.filter`` is a POSIX extended regular expression (as the standard says),
translated to Python's ``re`` by ``posix_ere_to_python``.
"""
from __future__ import annotations

import re
import string
from pathlib import Path
from typing import Callable
from urllib.parse import unquote, urlsplit

import numpy as np

from geometry_msgs.msg import Point, Pose, Quaternion, Twist, Vector3
from simulation_interfaces.msg import (Bounds, EntityCategory, EntityState, Result,
                                       Spawnable)
from simulation_interfaces.srv import (DeleteEntity, GetEntities, GetEntityState,
                                       GetSpawnables, SpawnEntity)
from std_msgs.msg import Header

from gripper_sim import configuration
from gripper_sim.convert import frames as frame_tree
from gripper_sim.convert.messages import time_msg, world_xyz
from gripper_sim.core.results import StepResult
from gripper_sim.errors import ConfigError
from gripper_sim.ros.simulation_standard import outcome

#: entity roles; each is also its entity's name, but the fruit's name changes with a spawn
FRUIT, LEFT_JAW, RIGHT_JAW, TABLE = 'fruit', 'left_jaw', 'right_jaw', 'table'
#: an entity name: a ROS name token (letters, digits, underscores; no leading digit)
ENTITY_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
CATEGORIES = {FRUIT: EntityCategory.CATEGORY_DYNAMIC_OBJECT,
              LEFT_JAW: EntityCategory.CATEGORY_ROBOT,
              RIGHT_JAW: EntityCategory.CATEGORY_ROBOT,
              TABLE: EntityCategory.CATEGORY_STATIC_OBJECT}
DELETE_REFUSALS = {
    FRUIT: 'the fruit cannot be deleted: the simulation always has exactly one fruit; '
           'spawn_entity with another preset replaces it',
    LEFT_JAW: 'the jaws are part of the gripper and cannot be deleted',
    RIGHT_JAW: 'the jaws are part of the gripper and cannot be deleted',
    TABLE: "the table is part of the world; start the node with physics.world.table "
           "false for a world without it"}


#: the POSIX character classes (C locale) as the contents of a Python ``re`` set
POSIX_CLASSES = {
    'alpha': 'A-Za-z', 'digit': '0-9', 'alnum': '0-9A-Za-z', 'upper': 'A-Z',
    'lower': 'a-z', 'xdigit': '0-9A-Fa-f', 'space': r' \t\n\r\f\v', 'blank': r' \t',
    'punct': ''.join(f'\\x{ord(c):02x}' for c in string.punctuation),
    'cntrl': r'\x00-\x1f\x7f', 'print': r'\x20-\x7e', 'graph': r'\x21-\x7e'}


class PatternError(ValueError):
    """A filter that is not a valid POSIX extended regular expression (the reason)."""


def entity_names(fruit_name: str, has_table: bool) -> dict[str, str]:
    """The entities of a world with or without a table, in a fixed order: ``{name: role}``
    (the fruit is named ``fruit_name``, the others by their role)."""
    return {fruit_name: FRUIT, LEFT_JAW: LEFT_JAW, RIGHT_JAW: RIGHT_JAW,
            **({TABLE: TABLE} if has_table else {})}


def literal(char: str) -> str:
    """``char`` as a literal in a Python ``re`` pattern, in a set or out of one (a hex
    escape unless alphanumeric)."""
    if char.isascii() and char.isalnum():
        return char
    return f'\\x{ord(char):02x}' if ord(char) < 0x100 else f'\\U{ord(char):08x}'


def bracket_element(pattern: str, at: int) -> tuple[str, str | None, int]:
    """The element of a bracket expression at ``pattern[at]``: (a Python set fragment,
    its character, or None for a character class, the index after it)."""
    for opener, closer in (('[:', ':]'), ('[=', '=]'), ('[.', '.]')):
        if pattern.startswith(opener, at):
            end = pattern.find(closer, at + 2)
            if end < 0:
                raise PatternError(f"'{opener}' at position {at} is not closed by "
                                   f"'{closer}'")
            name = pattern[at + 2:end]
            if opener == '[:':
                if name not in POSIX_CLASSES:
                    raise PatternError(f"unknown character class '[:{name}:]' (known: "
                                       f"{', '.join(sorted(POSIX_CLASSES))})")
                return POSIX_CLASSES[name], None, end + 2
            if len(name) != 1:
                raise PatternError(f"'{opener}{name}{closer}': only single-character "
                                   'collating elements are supported')
            return literal(name), name, end + 2
    return literal(pattern[at]), pattern[at], at + 1


def bracket_to_python(pattern: str, at: int) -> tuple[str, int]:
    """The POSIX bracket expression opening at ``pattern[at]`` (``[``) as a Python set,
    and the index after its closing ``]`` (a ``]`` first is a literal, as a ``-`` first
    or last is)."""
    start, at = at, at + 1
    negated = pattern.startswith('^', at)
    at += negated
    parts: list[str] = []
    while True:
        if at >= len(pattern):
            raise PatternError(f"the bracket expression at position {start} is not closed "
                               "by ']'")
        if pattern[at] == ']' and parts:
            return '[' + '^' * negated + ''.join(parts) + ']', at + 1
        low, low_char, at = bracket_element(pattern, at)
        if (low_char is None or not pattern.startswith('-', at) or at + 1 >= len(pattern)
                or pattern[at + 1] == ']'):
            parts.append(low)
            continue
        high, high_char, at = bracket_element(pattern, at + 1)
        if high_char is None:
            raise PatternError(f"the range starting '{low_char}-' ends in a character "
                               'class')
        if high_char < low_char:
            raise PatternError(f"the range '{low_char}-{high_char}' is reversed")
        parts.append(f'{low}-{high}')


def posix_ere_to_python(pattern: str) -> str:
    """The POSIX extended regular expression ``pattern`` (EntityFilters.filter) as a Python
    ``re`` pattern of the same meaning: bracket expressions with the character classes
    (``[[:alpha:]]`` ...) and single-character ``[=c=]``/``[.c.]``, a backslash quoting a
    special character; backreferences and Python's own escapes and ``(?`` groups, which
    ERE does not have, raise a PatternError."""
    translated: list[str] = []
    at = 0
    while at < len(pattern):
        char = pattern[at]
        if char == '[':
            text, at = bracket_to_python(pattern, at)
            translated.append(text)
            continue
        if char == '\\':
            if at + 1 >= len(pattern):
                raise PatternError('a trailing backslash quotes nothing')
            quoted = pattern[at + 1]
            if quoted.isdigit():
                raise PatternError(f"'\\{quoted}' is a backreference, which POSIX extended "
                                   'regular expressions do not have')
            if quoted.isalnum():
                raise PatternError(f"'\\{quoted}' is not a POSIX extended regular "
                                   'expression escape: use a bracket expression such as '
                                   '[[:digit:]], [[:alpha:]] or [[:space:]]')
            translated.append(literal(quoted))
            at += 2
            continue
        if pattern.startswith('(?', at):
            raise PatternError(f"'(?' at position {at}: a group cannot start with a "
                               "repetition ('(?...)' is Python's syntax, not POSIX)")
        translated.append(char)
        at += 1
    return ''.join(translated)


def compile_filter(text: str) -> re.Pattern | None:
    """The ``EntityFilters.filter`` ``text`` compiled (None when empty: every name).

    Raises:
        PatternError: it is not a valid POSIX extended regular expression (the reason).
    """
    if not text:
        return None
    try:
        return re.compile(posix_ere_to_python(text))
    except re.error as error:
        raise PatternError(str(error)) from None


def filtered(entities: dict[str, str], filters) -> tuple[list[str], Result]:
    """The names of ``entities`` (``{name: role}``) matching the ``EntityFilters``
    ``filters`` (a POSIX extended regular expression searched in the name, categories,
    tags: none of our entities has a tag), and the ``Result``: a bad pattern or a bounds
    filter (not supported) match nothing, with the reason."""
    if filters.bounds.type != Bounds.TYPE_EMPTY:
        return [], outcome(Result.RESULT_FEATURE_UNSUPPORTED, 'bounds filters are not supported')
    try:
        pattern = compile_filter(filters.filter)
    except PatternError as error:
        return [], outcome(Result.RESULT_OPERATION_FAILED,
                           f"invalid filter regex '{filters.filter}': {error} (filters "
                           'are POSIX extended regular expressions)')
    categories = {c.category for c in filters.categories}
    return [name for name, role in entities.items()
            if (pattern is None or pattern.search(name))
            and (not categories or CATEGORIES[role] in categories)
            and not filters.tags.tags], outcome()


def spawnable_description(name: str) -> str:
    """One line on the preset ``name``: model, shape and stiffness."""
    config = configuration.load_config(fruit=name)
    size = config.get('fruit.shape.diameter')
    size_text = f', {size * 1000:.1f} mm across' if size else ''
    return (f"{name}: {config['fruit.model']} model, {config['fruit.shape.type']}"
            f"{size_text}, E = {config['fruit.flesh.youngs_modulus'] / 1e6:.2f} MPa")


def entity_pose_twist(result: StepResult, entity: str, frames, table_height: float
                      ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """World position (m) and linear velocity (m/s) of ``entity`` in ``result``: the
    fruit's mass-weighted centroid and mean nodal velocity, the jaws' frame origins, the
    table's surface (at rest)."""
    if entity == FRUIT:
        centroid = world_xyz(np.reshape(result.centroid, (1, -1)))[0]
        velocity = world_xyz(np.mean(np.asarray(result.velocities), axis=0,
                                     keepdims=True))[0]
        return tuple(centroid.tolist()), tuple(velocity.tolist())
    if entity == TABLE:
        return (0.0, 0.0, table_height), (0.0, 0.0, 0.0)
    transforms = frame_tree.dynamic_transforms(result, frames)
    frame = frames.left_jaw if entity == LEFT_JAW else frames.right_jaw
    position = frame_tree.frame_position(transforms, frame)
    # a jaw closes towards the gripper centre; the left one sits on the left_outward side
    closing = float(result.jaw_velocity)
    side = frames.left_outward if entity == LEFT_JAW else -frames.left_outward
    velocity = (float(result.gripper_x_velocity) - side * closing, 0.0,
                float(result.lift_velocity))
    return tuple(position), velocity


class SpawnRefusal(Exception):
    """A refused spawn: its ``Result`` code and message."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.result = outcome(code, message)


def preset_source(uri: str) -> str:
    """The fruit preset ``uri`` names, as ``configuration.fruit_preset_path`` takes it: a
    preset name or a preset file path as they are, a ``file://`` URI as its path.

    Raises:
        SpawnRefusal: another URI scheme, or a file of another format than yaml.
    """
    parts = urlsplit(uri)
    if parts.scheme == 'file':
        if parts.netloc not in ('', 'localhost'):
            raise SpawnRefusal(SpawnEntity.Response.UNSUPPORTED_FORMAT,
                               f"'{uri}': only local file:// URIs are supported")
        source = unquote(parts.path)
    elif '://' in uri:
        raise SpawnRefusal(SpawnEntity.Response.UNSUPPORTED_FORMAT,
                           f"'{uri}': the URI scheme '{parts.scheme}' is not supported; "
                           'give a fruit preset name, a preset file path or a file:// URI')
    else:
        source = uri
    suffix = Path(source).suffix
    if suffix and not configuration.is_preset_file(source):
        raise SpawnRefusal(SpawnEntity.Response.UNSUPPORTED_FORMAT,
                           f"'{uri}': the format '{suffix}' is not supported; spawn a fruit "
                           f"preset ({', '.join(configuration.PRESET_SUFFIXES)})")
    return source


def unique_name(base: str, taken) -> str:
    """``base`` if it is not ``taken``, else ``base`` with the smallest suffix ``_<n>``
    (n >= 1) that is not."""
    name, number = base, 0
    while name in taken:
        number += 1
        name = f'{base}_{number}'
    return name


def spawn_name(request, preset_name: str, taken) -> str:
    """The name SpawnEntity gives the new fruit: the request's, else ``preset_name`` (the
    preset's ``fruit.name``, when it is a valid entity name); a missing or ``taken`` one
    generated from it (or from ``fruit``) when ``allow_renaming``.

    Raises:
        SpawnRefusal: ``NAME_INVALID`` or ``NAME_NOT_UNIQUE``, as SpawnEntity.srv says.
    """
    name = request.name or (preset_name if ENTITY_NAME.fullmatch(preset_name) else '')
    if not name:
        if request.allow_renaming:
            return unique_name(FRUIT, taken)
        raise SpawnRefusal(SpawnEntity.Response.NAME_INVALID,
                           'no name (and the preset names none): give one, or set '
                           'allow_renaming for a generated one')
    if name not in taken:
        return name
    if request.allow_renaming:
        return unique_name(name, taken)
    raise SpawnRefusal(SpawnEntity.Response.NAME_NOT_UNIQUE,
                       f"the name '{name}' is taken (entities: {', '.join(taken)}): give "
                       'another (the new fruit replaces the current one, whatever its '
                       'name) or set allow_renaming')


class EntityServices:
    """Serves the entity services of ``node`` (a ``SimNode``) in ``group``;
    ``replace_fruit(name_or_path) -> str | None`` swaps the fruit (an error message, or
    None when it was replaced)."""

    def __init__(self, node, group, replace_fruit: Callable[[str], str | None]):
        self._node = node
        self._replace_fruit = replace_fruit
        self._fruit_name = FRUIT
        self._startup_config = dict(node.params.config)
        self._spawned = False   # a spawned fruit replaced the start-up one
        #: configuration keys spawned presets set since then
        self._spawned_keys: set[str] = set()
        for srv, name, callback in (
                (GetEntities, 'get_entities', self._on_entities),
                (GetEntityState, 'get_entity_state', self._on_entity_state),
                (GetSpawnables, 'get_spawnables', self._on_spawnables),
                (SpawnEntity, 'spawn_entity', self._on_spawn),
                (DeleteEntity, 'delete_entity', self._on_delete)):
            node.create_service(srv, name, callback, callback_group=group)

    def _entities(self) -> dict[str, str]:
        return entity_names(self._fruit_name, bool(self._node.params.config['world.table']))

    def restore_startup_fruit(self) -> Result | None:
        """Bring back the start-up fruit (its configuration values and the name
        ``fruit``) if a spawn replaced it: the outcome (the replacement resets the
        simulation to t = 0), or None when no spawned fruit is in place."""
        if not self._spawned:
            return None
        problem = self._recording_problem()
        if problem:
            return problem
        keys = (self._spawned_keys | configuration.fruit_property_keys()
                | {key for key in self._startup_config if key.startswith('fruit.')})
        error = self._node.set_fruit(
            {key: self._startup_config[key] for key in keys},
            'the start-up fruit was restored (reset_simulation with SCOPE_SPAWNED)')
        if error:
            return outcome(Result.RESULT_OPERATION_FAILED,
                           f'the start-up fruit could not be restored: {error}')
        self._fruit_name = FRUIT
        self._spawned, self._spawned_keys = False, set()
        return outcome()

    def _on_entities(self, request, response):
        response.entities, response.result = filtered(self._entities(), request.filters)
        return response

    def _on_entity_state(self, request, response):
        node = self._node
        entities = self._entities()
        if request.entity not in entities:
            response.result = outcome(Result.RESULT_NOT_FOUND,
                                      f"no entity '{request.entity}' (entities: "
                                      f"{', '.join(entities)})")
            return response
        with node.lock:
            result = node.sim.last
            frames = node.message_context.frames
            table_height = float(node.params.config['world.table_height'])
        position, velocity = entity_pose_twist(result, entities[request.entity], frames,
                                               table_height)
        response.state = EntityState(
            header=Header(stamp=time_msg(result.time), frame_id=frames.scene),
            pose=Pose(position=Point(x=position[0], y=position[1], z=position[2]),
                      orientation=Quaternion(w=1.0)),
            twist=Twist(linear=Vector3(x=velocity[0], y=velocity[1], z=velocity[2])))
        response.result = outcome()
        return response

    def _on_spawnables(self, request, response):
        response.spawnables = [Spawnable(uri=name, description=spawnable_description(name))
                               for name in configuration.available_fruits()]
        response.result = outcome(message='' if not request.sources else (
            f"sources not searched: {', '.join(request.sources)} (only the built-in fruit "
            'presets are listed; a preset file path can still be spawned)'))
        return response

    def _on_spawn(self, request, response):
        try:
            response.entity_name = self._spawn(request)
            response.result = outcome()
        except SpawnRefusal as refusal:
            response.result = refusal.result
        return response

    def _spawn(self, request) -> str:
        """Replace the fruit as ``request`` asks; the new fruit's entity name.

        Raises:
            SpawnRefusal: the request is refused (nothing changed).
        """
        if request.name and not ENTITY_NAME.fullmatch(request.name):
            raise SpawnRefusal(SpawnEntity.Response.NAME_INVALID,
                               f"invalid name '{request.name}': entity names are letters, "
                               'digits and underscores, not starting with a digit')
        if request.entity_namespace:
            raise SpawnRefusal(SpawnEntity.Response.NAMESPACE_INVALID,
                               'entity namespaces are not supported')
        if not request.uri:
            if request.resource_string:
                raise SpawnRefusal(Result.RESULT_FEATURE_UNSUPPORTED,
                                   'resource_string is not supported (no '
                                   'SPAWNING_RESOURCE_STRING feature): give a uri')
            raise SpawnRefusal(SpawnEntity.Response.NO_RESOURCE,
                               'no uri: give a fruit preset name (get_spawnables), a preset '
                               'file path or a file:// URI')
        pose = request.initial_pose.pose
        if (pose.position.x, pose.position.y, pose.position.z) != (0.0, 0.0, 0.0) or \
                (pose.orientation.x, pose.orientation.y, pose.orientation.z,
                 pose.orientation.w) != (0.0, 0.0, 0.0, 1.0):
            raise SpawnRefusal(SpawnEntity.Response.INVALID_POSE,
                               'the fruit always starts at rest on the table; leave '
                               'initial_pose at its default')
        source = preset_source(request.uri)
        try:
            path = configuration.fruit_preset_path(source)
        except ConfigError as error:
            raise SpawnRefusal(Result.RESULT_NOT_FOUND, f'{error}') from None
        try:
            keys = configuration.flatten(configuration.read_yaml(path))
        except ConfigError as error:
            raise SpawnRefusal(SpawnEntity.Response.RESOURCE_PARSE_ERROR, f'{error}') from None
        name = spawn_name(request, str(keys.get('fruit.name') or ''), list(self._entities()))
        problem = self._recording_problem()
        if problem:
            raise SpawnRefusal(problem.result, problem.error_message)
        error = self._replace_fruit(source)
        if error:
            raise SpawnRefusal(SpawnEntity.Response.RESOURCE_PARSE_ERROR, error)
        self._fruit_name, self._spawned = name, True
        self._spawned_keys |= {key for key in keys if key in configuration.SCHEMA}
        return name

    def _recording_problem(self) -> Result | None:
        recording = self._node.recording_control.recording
        if recording is not None and recording.active:
            return outcome(Result.RESULT_INCORRECT_STATE,
                           'a recording is running and names the current fruit; stop it '
                           '(~/record false) before replacing the fruit')
        return None

    def _on_delete(self, request, response):
        role = self._entities().get(request.entity)
        response.result = (outcome(Result.RESULT_OPERATION_FAILED, DELETE_REFUSALS[role])
                           if role else outcome(Result.RESULT_NOT_FOUND,
                                                f"no entity '{request.entity}'"))
        return response
