"""QoS profiles as rosbag2 (Jazzy, metadata version 9) stores them.

A channel's ``offered_qos_profiles`` metadata is a YAML list of profiles, one per
publisher seen, each with string policy names::

    - history: keep_last
      depth: 10
      reliability: reliable
      durability: volatile
      deadline:
        sec: 9223372036
        nsec: 854775807
      ...

Profiles are handled here as plain dicts (the YAML shape) so that files can be written
and read without rclpy; ``from_rclpy``/``to_rclpy`` convert at the ROS boundary.
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping

import yaml

from gripper_sim.configuration import yaml_problem
from gripper_sim.recording.errors import RecordingError

INFINITE_NS = 9223372036854775807  # RMW_DURATION_INFINITE, what Fast DDS reports
POLICY_KEYS = ('history', 'reliability', 'durability', 'liveliness')
DURATION_KEYS = ('deadline', 'lifespan', 'liveliness_lease_duration')
KEY_ORDER = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
             'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')

# rmw policy enum values (rmw/types.h), for files that store integers (metadata <= 8)
_INT_NAMES = {
    'history': {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'},
    'reliability': {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown',
                    4: 'best_available'},
    'durability': {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown',
                   4: 'best_available'},
    'liveliness': {0: 'system_default', 1: 'automatic', 3: 'manual_by_topic', 4: 'unknown',
                   5: 'best_available'},
}


def default_profile(*, reliability: str = 'reliable', durability: str = 'volatile',
                    depth: int = 10) -> dict[str, Any]:
    """A keep-last profile with no deadline, lifespan or lease (rclpy's defaults)."""
    return {
        'history': 'keep_last', 'depth': depth, 'reliability': reliability,
        'durability': durability, 'deadline': 0, 'lifespan': 0, 'liveliness': 'automatic',
        'liveliness_lease_duration': 0, 'avoid_ros_namespace_conventions': False,
    }


def _ns(value: Any) -> int:
    """A duration given as ns or as a {sec, nsec} mapping -> ns."""
    if isinstance(value, Mapping):
        return int(value.get('sec', 0)) * 1_000_000_000 + int(value.get('nsec', 0))
    return int(value or 0)


def normalize(profile: Mapping[str, Any]) -> dict[str, Any]:
    """A profile dict with string policies and durations in integer ns."""
    out = default_profile()
    for key in KEY_ORDER:
        if key not in profile:
            continue
        value = profile[key]
        if key in POLICY_KEYS:
            if isinstance(value, bool) or not isinstance(value, (int, str)):
                raise RecordingError(f'QoS {key} {value!r} is neither a name nor a number')
            if isinstance(value, int):
                value = _INT_NAMES[key].get(value, 'unknown')
            out[key] = str(value).lower()
        elif key in DURATION_KEYS:
            out[key] = _ns(value)
        elif key == 'depth':
            out[key] = int(value)
        else:
            out[key] = bool(value)
    return out


def _duration_yaml(ns: int, indent: str) -> str:
    return f'\n{indent}  sec: {ns // 1_000_000_000}\n{indent}  nsec: {ns % 1_000_000_000}'


def to_yaml(profiles: Iterable[Mapping[str, Any]]) -> str:
    """Serialize profiles as rosbag2 writes ``offered_qos_profiles`` (yaml-cpp layout)."""
    blocks = []
    for raw in profiles:
        p = normalize(raw)
        lines = []
        for i, key in enumerate(KEY_ORDER):
            lead = '- ' if i == 0 else '  '
            value = p[key]
            if key in DURATION_KEYS:
                lines.append(f'{lead}{key}:{_duration_yaml(value, "  ")}')
            elif isinstance(value, bool):
                lines.append(f'{lead}{key}: {"true" if value else "false"}')
            else:
                lines.append(f'{lead}{key}: {value}')
        blocks.append('\n'.join(lines))
    return '\n'.join(blocks) if blocks else '[]'


def from_yaml(text: str) -> list[dict[str, Any]]:
    """Parse an ``offered_qos_profiles`` string (empty -> no profiles)."""
    if not text or not text.strip():
        return []
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise RecordingError(f'offered_qos_profiles is not valid YAML: '
                             f'{yaml_problem(err)}') from None
    except RecursionError:
        raise RecordingError('offered_qos_profiles is not valid YAML: it nests too '
                             'deeply') from None
    if data is None:
        return []
    if not isinstance(data, list) or not all(isinstance(p, Mapping) for p in data):
        raise RecordingError('offered_qos_profiles is not a list of QoS profiles')
    return [normalize(p) for p in data]


def adapt_for_replay(profiles: list[Mapping[str, Any]]) -> dict[str, Any]:
    """One profile to publish with, offering what the recorded publishers offered.

    As rosbag2 does: when every recorded publisher offered the same compatibility-relevant
    policies, offer those (with keep-last history); otherwise the defaults.
    """
    if not profiles:
        return default_profile()
    norm = [normalize(p) for p in profiles]
    keys = ('reliability', 'durability', 'deadline', 'liveliness', 'liveliness_lease_duration')
    first = norm[0]
    if any(any(p[k] != first[k] for k in keys) for p in norm[1:]):
        return default_profile()
    out = dict(first)
    out['history'] = 'keep_last'
    out['depth'] = max(int(first.get('depth') or 0), 10)
    for key in ('reliability', 'durability', 'liveliness'):
        if out[key] in ('unknown', 'best_available'):
            out[key] = default_profile()[key]
    return out


def from_rclpy(qos: Any) -> dict[str, Any]:
    """An rclpy ``QoSProfile`` (e.g. from ``TopicEndpointInfo.qos_profile``) -> profile dict."""
    def name(policy: Any) -> str:
        return str(getattr(policy, 'name', policy)).lower()

    return normalize({
        'history': name(qos.history),
        'depth': int(qos.depth),
        'reliability': name(qos.reliability),
        'durability': name(qos.durability),
        'deadline': int(qos.deadline.nanoseconds),
        'lifespan': int(qos.lifespan.nanoseconds),
        'liveliness': name(qos.liveliness),
        'liveliness_lease_duration': int(qos.liveliness_lease_duration.nanoseconds),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    })


def to_rclpy(profile: Mapping[str, Any]) -> Any:
    """Profile dict -> rclpy ``QoSProfile`` (infinite durations left at rclpy's default)."""
    from rclpy.duration import Duration
    from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile,
                           ReliabilityPolicy)

    p = normalize(profile)

    def enum(cls: Any, value: str, fallback: Any) -> Any:
        try:
            member = cls[value.upper()]
        except KeyError:
            return fallback
        if value in ('unknown',):
            return fallback
        return member

    kwargs: dict[str, Any] = {
        'history': enum(HistoryPolicy, p['history'], HistoryPolicy.KEEP_LAST),
        'depth': max(int(p['depth']), 1),
        'reliability': enum(ReliabilityPolicy, p['reliability'], ReliabilityPolicy.RELIABLE),
        'durability': enum(DurabilityPolicy, p['durability'], DurabilityPolicy.VOLATILE),
        'liveliness': enum(LivelinessPolicy, p['liveliness'], LivelinessPolicy.AUTOMATIC),
        'avoid_ros_namespace_conventions': p['avoid_ros_namespace_conventions'],
    }
    for key in DURATION_KEYS:
        ns = p[key]
        if 0 < ns < INFINITE_NS:
            kwargs[key] = Duration(nanoseconds=ns)
    return QoSProfile(**kwargs)
