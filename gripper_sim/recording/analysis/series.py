"""Runs and time series of a recorded grasp, read from the MCAP file alone.

One row per ``FruitState`` message of the sim node, with the jaw wrenches and the lift
joint (``/joint_states``) matched by header stamp. A recording may hold several runs:
a ``~/reset`` (or a recovery) sets the sim time back to 0, and ``split_runs`` cuts the
series wherever the stamp goes back, so that each run is analysed on its own.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable

import numpy as np
import yaml

from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.reader import BagReader

FRUIT_STATE_TYPE = 'gripper_sim_interfaces/msg/FruitState'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'
JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
CONFIG_METADATA = 'gripper_sim_config'
DEFAULT_BRUISE_PRESSURE = 0.26e6  # Pa, the configuration default
#: the name of the gripper's vertical joint in ``/joint_states`` (its position: m)
LIFT_JOINT = 'lift_joint'

COLUMNS = (
    'time_s', 'gap_m', 'grip_force_n', 'left_force_n', 'right_force_n', 'compression_m',
    'compression_ratio', 'max_skin_strain', 'peak_contact_pressure_pa', 'contact_length_m',
    'slip_distance_m', 'slipping', 'left_jaw_contact', 'right_jaw_contact',
    'kinetic_energy_j', 'elastic_energy_j', 'gravitational_energy_j', 'total_energy_j',
    'centroid_x_m', 'centroid_z_m', 'bruised', 'bruised_fraction', 'crushed',
    'dimension', 'contact_area_m2', 'centroid_y_m', 'damage_pressure_pa',
    'peak_damage_pressure_pa', 'peak_flesh_stress_pa', 'lift_m',
)
#: the FruitState field older recordings lack (their column is empty)
DAMAGE_PRESSURE_FIELD = 'peak_damage_pressure'

#: called as ``progress(done, total)`` while the messages are read (counts of messages)
Progress = Callable[[int, int], None]


def stamp_ns(header: Any) -> int:
    """Integer ns of a decoded ``std_msgs/Header``."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


@dataclass
class TimeSeries:
    """Columns of ``COLUMNS`` as (n,) numpy arrays, plus per row the log time and the
    header stamp of its FruitState message (ns).

    ``lift_m`` is NaN when the recording has no ``/joint_states``.
    """

    columns: dict[str, np.ndarray]
    log_times: np.ndarray
    stamps: np.ndarray
    has_damage_pressure: bool = True

    @property
    def dimension(self) -> int:
        """2 or 3: the model dimension the FruitState messages report."""
        return int(np.max(self.columns['dimension'])) if len(self) else 2

    @property
    def has_lift(self) -> bool:
        """Whether the lift joint was recorded (``/joint_states``)."""
        return bool(np.any(np.isfinite(self.columns['lift_m'])))

    def __len__(self) -> int:
        return len(self.log_times)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def rows(self, start: int, stop: int) -> TimeSeries:
        """The rows ``start:stop`` as a series of their own."""
        return TimeSeries(columns={k: v[start:stop] for k, v in self.columns.items()},
                          log_times=self.log_times[start:stop],
                          stamps=self.stamps[start:stop],
                          has_damage_pressure=self.has_damage_pressure)


def run_starts(stamps: Iterable[int]) -> np.ndarray:
    """Indices (k,) where a run starts: 0 and every index whose stamp is below the one
    before it (the sim time went back: a reset)."""
    values = np.asarray(list(stamps) if not isinstance(stamps, np.ndarray) else stamps,
                        dtype=np.int64)
    if values.size == 0:
        return np.zeros(0, dtype=int)
    back = np.flatnonzero(np.diff(values) < 0) + 1
    return np.concatenate([[0], back]).astype(int)


def run_index(stamps: Iterable[int]) -> np.ndarray:
    """(n,) the run number (0, 1, ...) of every stamp of one topic, in log order."""
    values = np.asarray(list(stamps), dtype=np.int64)
    index = np.zeros(values.size, dtype=int)
    if values.size:
        index[run_starts(values)[1:]] = 1
    return np.cumsum(index)


def split_runs(series: TimeSeries) -> list[TimeSeries]:
    """The runs of ``series``: one per stretch of non-decreasing sim time."""
    starts = list(run_starts(series.stamps)) + [len(series)]
    return [series.rows(a, b) for a, b in zip(starts[:-1], starts[1:]) if b > a]


def find_topics(bag: BagReader, namespace: str | None = None) -> dict[str, str | None]:
    """Topic names of the sim node's outputs in ``bag``: state, wrenches, markers, node
    cloud and joint states (None for the ones not recorded)."""
    states = [t for t, info in bag.topics.items() if info.type == FRUIT_STATE_TYPE]
    if namespace is not None:
        prefix = '/' + namespace.strip('/') if namespace.strip('/') else ''
        wanted = f'{prefix}/fruit/state'
        if wanted not in states:
            msg = (f"{bag.path} has no FruitState topic '{wanted}' (FruitState topics: "
                   f"{', '.join(states) or 'none'})")
            raise RecordingError(msg)
        state = wanted
    elif not states:
        msg = (f'{bag.path} has no {FRUIT_STATE_TYPE} topic: record the sim node\'s '
               "'~/fruit/state' topic (e.g. 'gripper-sim record --all')")
        raise RecordingError(msg)
    elif len(states) > 1:
        msg = (f"{bag.path} has several FruitState topics ({', '.join(states)}); choose one "
               'with --namespace')
        raise RecordingError(msg)
    else:
        state = states[0]
    prefix = state[:-len('/fruit/state')] if state.endswith('/fruit/state') else \
        state.rsplit('/', 1)[0]

    def optional(name: str, type_name: str) -> str | None:
        info = bag.topics.get(name)
        return info.name if info is not None and info.type == type_name else None

    node_prefix = prefix.rsplit('/', 1)[0]   # joint_states is relative to the namespace
    return {
        'state': state,
        'left': optional(f'{prefix}/left_jaw/wrench', WRENCH_TYPE),
        'right': optional(f'{prefix}/right_jaw/wrench', WRENCH_TYPE),
        'markers': optional(f'{prefix}/markers', MARKERS_TYPE),
        'nodes': optional(f'{prefix}/fruit/nodes', CLOUD_TYPE),
        'joints': optional(f'{node_prefix}/joint_states', JOINT_STATE_TYPE),
    }


def read_config(bag: BagReader) -> dict[str, Any]:
    """The flat configuration stored in the file by the sim, or {}."""
    record = bag.metadata_named(CONFIG_METADATA)
    if not record or 'yaml' not in record:
        return {}
    try:
        tree = yaml.safe_load(record['yaml'])
    except yaml.YAMLError:
        return {}
    if not isinstance(tree, dict):
        return {}
    flat: dict[str, Any] = {}

    def walk(node: dict, prefix: str) -> None:
        for key, value in node.items():
            if isinstance(value, dict):
                walk(value, f'{prefix}{key}.')
            else:
                flat[f'{prefix}{key}'] = value
    walk(tree, '')
    return flat


def _values_by_run_and_stamp(bag: BagReader, topic: str | None,
                             value: Callable[[Any], float]) -> dict[tuple[int, int], float]:
    """{(run number, stamp ns): value(msg)} of every message of ``topic`` (runs counted
    from the topic's own stamps, so that stamps repeated after a reset do not mix)."""
    if topic is None:
        return {}
    stamps, values = [], []
    for _raw, msg in bag.decoded_messages([topic]):
        stamps.append(stamp_ns(msg.header))
        values.append(value(msg))
    runs = run_index(stamps)
    return {(int(r), s): v for r, s, v in zip(runs, stamps, values)}


def _lift_position(msg: Any) -> float:
    names = list(msg.name)
    if LIFT_JOINT in names and len(msg.position) > names.index(LIFT_JOINT):
        return float(msg.position[names.index(LIFT_JOINT)])
    return math.nan


def read_time_series(bag: BagReader, topics: dict[str, str | None],
                     progress: Progress | None = None) -> TimeSeries:
    """One row per FruitState message, with per-jaw normal forces and the lift height
    matched by run and stamp.

    Raises:
        RecordingError: the state topic holds no messages.
    """
    state_topic = topics['state']
    if state_topic is None:
        raise RecordingError('no FruitState topic to read')
    left = _values_by_run_and_stamp(bag, topics['left'], lambda m: abs(m.wrench.force.x))
    right = _values_by_run_and_stamp(bag, topics['right'], lambda m: abs(m.wrench.force.x))
    lift = _values_by_run_and_stamp(bag, topics.get('joints'), _lift_position)
    total = bag.topics[state_topic].message_count
    rows: list[list[float]] = []
    log_times: list[int] = []
    stamps: list[int] = []
    has_damage_pressure = True
    run, last_stamp = 0, None
    for raw, s in bag.decoded_messages([state_topic]):
        stamp = stamp_ns(s.header)
        if last_stamp is not None and stamp < last_stamp:
            run += 1
        last_stamp = stamp
        if getattr(s, DAMAGE_PRESSURE_FIELD, None) is None:
            has_damage_pressure = False
        damage = [getattr(s, name, None) for name in
                  ('damage_pressure', DAMAGE_PRESSURE_FIELD, 'peak_flesh_stress')]
        key = (run, stamp)
        rows.append([
            stamp / 1e9, s.gap, s.grip_force, left.get(key, math.nan),
            right.get(key, math.nan), s.compression, s.compression_ratio,
            s.max_skin_strain, s.peak_contact_pressure, s.contact_length, s.slip_distance,
            float(s.slipping), float(s.left_jaw_contact), float(s.right_jaw_contact),
            s.kinetic_energy, s.elastic_energy, s.gravitational_energy,
            s.kinetic_energy + s.elastic_energy + s.gravitational_energy,
            s.centroid.x, s.centroid.z, float(s.bruised), s.bruised_fraction,
            float(s.crushed), float(s.dimension or 2), s.contact_area, s.centroid.y,
            *(math.nan if value is None else float(value) for value in damage),
            lift.get(key, math.nan),
        ])
        log_times.append(raw.log_time)
        stamps.append(stamp)
        if progress is not None and len(rows) % 200 == 0:
            progress(len(rows), total)
    if not rows:
        raise RecordingError(f"{bag.path}: topic '{state_topic}' holds no messages")
    if progress is not None:
        progress(len(rows), total)
    data = np.asarray(rows, dtype=float)
    columns = {name: data[:, i] for i, name in enumerate(COLUMNS)}
    return TimeSeries(columns=columns, log_times=np.asarray(log_times, dtype=np.int64),
                      stamps=np.asarray(stamps, dtype=np.int64),
                      has_damage_pressure=has_damage_pressure)
