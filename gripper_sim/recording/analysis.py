"""Offline analysis of a recorded grasp, from the MCAP file alone (no ROS graph).

Reads the sim node's ``FruitState`` topic (and, when recorded, the two jaw wrenches, the
markers and the node point cloud), and writes:

- ``timeseries.csv``: one row per FruitState message (sim time, gap, grip force per jaw,
  compression, max strain, peak contact pressure, contact length and area, slip,
  energies, centroid, damage flags);
- ``summary.json``: peak force and compression, stiffness from the force-compression
  curve, contact size (length in 2D, area in 3D), held/slipped, damage (bruised,
  bruised fraction, peak damage pressure, crushed), time above the bruise threshold;
- ``force_vs_time.png``, ``force_vs_compression.png``; for a 2D run
  ``outline_snapshots.png`` (the fruit outline at key moments coloured by skin strain
  and by contact pressure); for a 3D run ``mesh_snapshots.png`` (the deformed skin at
  key moments, from the ``fruit_mesh`` TRIANGLE_LIST marker, coloured by contact
  pressure) and ``contact_patch.png`` (the jaw contact nodes of the point cloud at peak
  force projected onto the jaw plane y-z, with their outline and area).

Damage comes from the recorded ``FruitState`` fields (``bruised``, ``bruised_fraction``,
``crushed``, ``damage_pressure``, ``peak_damage_pressure``, ``peak_flesh_stress``: the
simulation's damage estimate, Hertz in 2D and resolved in 3D); the time above the
bruise threshold counts the samples whose ``damage_pressure`` exceeds it. A recording
made before these fields existed lacks them: the summary says so
(``peak_damage_pressure_pa`` null, ``damage_note``) and falls back to the peak contact
pressure (bruised: the flag, or the peak contact pressure above the threshold).

Messages are decoded with ``mcap-ros2-support``'s decoder from the schemas stored in
the file, so the analysis runs without ROS installed.
"""
from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import yaml

from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.reader import BagReader

FRUIT_STATE_TYPE = 'gripper_sim_interfaces/msg/FruitState'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
CLOUD_TYPE = 'sensor_msgs/msg/PointCloud2'
CONFIG_METADATA = 'gripper_sim_config'
DEFAULT_BRUISE_PRESSURE = 0.26e6  # Pa, the configuration default
SLIP_THRESHOLD = 1e-3  # m of slip that counts as "slipped"

COLUMNS = (
    'time_s', 'gap_m', 'grip_force_n', 'left_force_n', 'right_force_n', 'compression_m',
    'compression_ratio', 'max_skin_strain', 'peak_contact_pressure_pa', 'contact_length_m',
    'slip_distance_m', 'slipping', 'left_jaw_contact', 'right_jaw_contact',
    'kinetic_energy_j', 'elastic_energy_j', 'gravitational_energy_j', 'total_energy_j',
    'centroid_x_m', 'centroid_z_m', 'bruised', 'bruised_fraction', 'crushed',
    'dimension', 'contact_area_m2', 'centroid_y_m', 'damage_pressure_pa',
    'peak_damage_pressure_pa', 'peak_flesh_stress_pa',
)
#: the FruitState field older recordings lack (their column is empty)
DAMAGE_PRESSURE_FIELD = 'peak_damage_pressure'


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


@dataclass
class TimeSeries:
    """Columns of ``COLUMNS`` as numpy arrays, plus the log time of each row (ns)."""

    columns: dict[str, np.ndarray]
    log_times: np.ndarray
    stamps: np.ndarray
    has_damage_pressure: bool = True

    @property
    def dimension(self) -> int:
        """2 or 3: the model dimension the FruitState messages report."""
        return int(np.max(self.columns['dimension'])) if len(self) else 2

    def __len__(self) -> int:
        return len(self.log_times)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]


@dataclass
class AnalysisResult:
    """What ``analyze`` wrote."""

    summary: dict
    output_dir: Path
    files: list[Path] = field(default_factory=list)

    def describe(self) -> list[str]:
        s = self.summary

        def fmt(value: Any, unit: str, scale: float = 1.0, digits: int = 3) -> str:
            if value is None:
                return 'n/a'
            return f'{value * scale:.{digits}f} {unit}'

        three_d = s.get('dimension') == 3
        if three_d:
            area = fmt(s['contact_area_at_peak_force_m2'], 'mm^2', 1e6, 1)
            largest = fmt(s['peak_contact_area_m2'], 'mm^2', 1e6, 1)
            contact = f'contact area:          {area} at peak force (largest {largest})'
        else:
            length = fmt(s['contact_length_at_peak_force_m'], 'mm', 1e3)
            contact = f'contact length:        {length} at peak force'
        damage = (f"damage:                bruised {s['bruised']} "
                  f"({100 * s['bruised_fraction']:.1f} % of the "
                  f"{'surface' if three_d else 'outline'}), peak damage pressure "
                  f"{fmt(s['peak_damage_pressure_pa'], 'kPa', 1e-3, 1)}, crushed {s['crushed']}")
        lines = [
            f"analysed {s['samples']} FruitState messages on {s['fruit_state_topic']} "
            f"({s['duration_s']:.3f} s of sim time, {s.get('dimension', 2)}D model)",
            f"peak grip force:       {fmt(s['peak_grip_force_n'], 'N')} at "
            f"{fmt(s['time_of_peak_force_s'], 's')}",
            f"peak compression:      {fmt(s['peak_compression_m'], 'mm', 1e3)}",
            f"stiffness:             {fmt(s['stiffness_n_per_m'], 'N/mm', 1e-3)} (tangent), "
            f"{fmt(s['secant_stiffness_n_per_m'], 'N/mm', 1e-3)} (secant)",
            f"peak contact pressure: {fmt(s['peak_contact_pressure_pa'], 'kPa', 1e-3, 1)}",
            f"held: {s['held']}   slipped: {s['slipped']} (max slip "
            f"{fmt(s['max_slip_distance_m'], 'mm', 1e3)})",
            contact,
            damage,
            f"time above bruise threshold (damage pressure): "
            f"{fmt(s['time_above_bruise_threshold_s'], 's')}",
        ]
        if s.get('damage_note'):
            lines.append(f"note: {s['damage_note']}")
        lines += [f'wrote {p}' for p in self.files]
        return lines


# ---------------------------------------------------------------------- topics
def find_topics(bag: BagReader, namespace: str | None = None) -> dict[str, str | None]:
    """Topic names of the sim node's outputs in ``bag``: state, wrenches, markers."""
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
        info = bag.topics.get(f'{prefix}/{name}')
        return info.name if info is not None and info.type == type_name else None

    return {
        'state': state,
        'left': optional('left_jaw/wrench', WRENCH_TYPE),
        'right': optional('right_jaw/wrench', WRENCH_TYPE),
        'markers': optional('markers', MARKERS_TYPE),
        'nodes': optional('fruit/nodes', CLOUD_TYPE),
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


def read_time_series(bag: BagReader, topics: dict[str, str | None]) -> TimeSeries:
    """One row per FruitState message, with per-jaw normal forces matched by stamp."""
    jaw_force: dict[str, dict[int, float]] = {'left': {}, 'right': {}}
    for side in ('left', 'right'):
        topic = topics[side]
        if topic is None:
            continue
        for _raw, msg in bag.decoded_messages([topic]):
            jaw_force[side][_stamp_ns(msg.header)] = abs(float(msg.wrench.force.x))
    rows: list[list[float]] = []
    log_times: list[int] = []
    stamps: list[int] = []
    state_topic = topics['state']
    assert state_topic is not None
    has_damage_pressure = True
    for raw, s in bag.decoded_messages([state_topic]):
        stamp = _stamp_ns(s.header)
        peak_damage = getattr(s, DAMAGE_PRESSURE_FIELD, None)
        if peak_damage is None:
            has_damage_pressure = False
        damage = [getattr(s, name, None) for name in
                  ('damage_pressure', DAMAGE_PRESSURE_FIELD, 'peak_flesh_stress')]
        rows.append([
            stamp / 1e9, s.gap, s.grip_force,
            jaw_force['left'].get(stamp, math.nan), jaw_force['right'].get(stamp, math.nan),
            s.compression, s.compression_ratio, s.max_skin_strain, s.peak_contact_pressure,
            s.contact_length, s.slip_distance, float(s.slipping), float(s.left_jaw_contact),
            float(s.right_jaw_contact), s.kinetic_energy, s.elastic_energy,
            s.gravitational_energy, s.kinetic_energy + s.elastic_energy + s.gravitational_energy,
            s.centroid.x, s.centroid.z, float(s.bruised), s.bruised_fraction, float(s.crushed),
            float(s.dimension or 2), s.contact_area, s.centroid.y,
            *(math.nan if value is None else float(value) for value in damage),
        ])
        log_times.append(raw.log_time)
        stamps.append(stamp)
    if not rows:
        raise RecordingError(f"{bag.path}: topic '{topics['state']}' holds no messages")
    data = np.asarray(rows, dtype=float)
    columns = {name: data[:, i] for i, name in enumerate(COLUMNS)}
    return TimeSeries(columns=columns, log_times=np.asarray(log_times, dtype=np.int64),
                      stamps=np.asarray(stamps, dtype=np.int64),
                      has_damage_pressure=has_damage_pressure)


# ---------------------------------------------------------------------- summary
def _finite_or_none(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def loading_curve(series: TimeSeries) -> tuple[np.ndarray, np.ndarray]:
    """(compression, force) of the loading part: both jaws touching, up to peak force."""
    force = series['grip_force_n']
    compression = series['compression_m']
    peak = int(np.argmax(force))
    touching = (series['left_jaw_contact'] > 0) & (series['right_jaw_contact'] > 0)
    mask = touching.copy()
    mask[peak + 1:] = False
    mask &= compression > 0
    return compression[mask], force[mask]


def stiffness(series: TimeSeries) -> tuple[float | None, float | None]:
    """(tangent, secant) stiffness in N/m from the loading force-compression curve.

    Tangent: least-squares slope over the loading samples above 20 % of the peak force
    (the near-linear upper part of the curve). Secant: peak force over the compression
    at that moment. None when the jaws never both touched.
    """
    compression, force = loading_curve(series)
    if compression.size == 0:
        return None, None
    peak_force = float(force.max())
    at_peak = float(compression[int(np.argmax(force))])
    secant = peak_force / at_peak if at_peak > 0 else None
    upper = force >= 0.2 * peak_force
    x, y = compression[upper], force[upper]
    tangent = None
    if x.size >= 3 and float(np.ptp(x)) > 0:
        tangent = float(np.polyfit(x, y, 1)[0])
    return tangent, secant


def summarize(series: TimeSeries, *, bruise_pressure: float,
              slip_threshold: float = SLIP_THRESHOLD) -> dict[str, Any]:
    """The numbers a person looks at first, from a time series."""
    t = series['time_s']
    force = series['grip_force_n']
    peak = int(np.argmax(force))
    dt = np.diff(t, append=t[-1])
    dt[dt < 0] = 0.0
    # the damage estimate's pressure (2D: Hertz, 3D: resolved); older recordings: the
    # peak contact pressure
    pressure = series['damage_pressure_pa'] if series.has_damage_pressure \
        else series['peak_contact_pressure_pa']
    over = pressure > bruise_pressure
    tangent, secant = stiffness(series)
    both = (series['left_jaw_contact'] > 0) & (series['right_jaw_contact'] > 0)
    max_slip = float(np.max(np.abs(series['slip_distance_m'])))
    end_slip = float(abs(series['slip_distance_m'][-1]))
    slipping_time = float(np.sum(dt[series['slipping'] > 0]))
    held = bool(both[-1] and series['slipping'][-1] == 0 and end_slip < slip_threshold)
    left = series['left_force_n']
    right = series['right_force_n']
    bruised_flag = bool(np.any(series['bruised'] > 0))
    if series.has_damage_pressure:
        damage_pressure = _finite_or_none(np.max(series['peak_damage_pressure_pa']))
        bruised = bruised_flag
        note = None
    else:
        damage_pressure = None
        bruised = bruised_flag or bool(np.any(over))
        note = (f'the FruitState messages of this recording have no '
                f"'{DAMAGE_PRESSURE_FIELD}' field (recorded before it was added): the peak "
                'damage pressure is not available; bruised is the recorded flag or the '
                'peak contact pressure above the threshold')
    return {
        'dimension': series.dimension,
        'samples': len(series),
        'duration_s': float(t[-1] - t[0]),
        'start_time_s': float(t[0]),
        'peak_grip_force_n': float(force[peak]),
        'time_of_peak_force_s': float(t[peak]),
        'peak_left_force_n': _finite_or_none(np.nanmax(left)) if np.any(np.isfinite(left))
        else None,
        'peak_right_force_n': _finite_or_none(np.nanmax(right))
        if np.any(np.isfinite(right)) else None,
        'peak_compression_m': float(np.max(series['compression_m'])),
        'peak_compression_ratio': float(np.max(series['compression_ratio'])),
        'compression_at_peak_force_m': float(series['compression_m'][peak]),
        'stiffness_n_per_m': tangent,
        'secant_stiffness_n_per_m': secant,
        'peak_contact_pressure_pa': float(np.max(series['peak_contact_pressure_pa'])),
        'peak_max_skin_strain': float(series['max_skin_strain'][
            int(np.argmax(np.abs(series['max_skin_strain'])))]),
        'gripped': bool(np.any(both)),
        'held': held,
        'slipped': bool(max_slip >= slip_threshold or slipping_time > 0),
        'max_slip_distance_m': max_slip,
        'final_slip_distance_m': end_slip,
        'slipping_time_s': slipping_time,
        'peak_contact_length_m': float(np.max(series['contact_length_m'])),
        'contact_length_at_peak_force_m': float(series['contact_length_m'][peak]),
        'peak_contact_area_m2': float(np.max(series['contact_area_m2'])),
        'contact_area_at_peak_force_m2': float(series['contact_area_m2'][peak]),
        'bruised': bruised,
        'bruised_fraction': float(np.max(series['bruised_fraction'])),
        'final_bruised_fraction': float(series['bruised_fraction'][-1]),
        'peak_damage_pressure_pa': damage_pressure,
        'peak_flesh_stress_pa': _finite_or_none(np.max(series['peak_flesh_stress_pa']))
        if series.has_damage_pressure else None,
        'crushed': bool(np.any(series['crushed'] > 0)),
        'damage_note': note,
        'bruise_threshold_pa': float(bruise_pressure),
        'time_above_bruise_threshold_s': float(np.sum(dt[over])),
        'first_contact_time_s': float(t[int(np.argmax(both))]) if np.any(both) else None,
        'slip_threshold_m': slip_threshold,
    }


def write_csv(series: TimeSeries, path: Path) -> None:
    with open(path, 'w', newline='', encoding='utf-8') as f:
        writer = csv.writer(f)
        writer.writerow(COLUMNS)
        data = np.column_stack([series[c] for c in COLUMNS])
        for row in data:
            writer.writerow([repr(float(v)) if math.isfinite(v) else '' for v in row])


# ---------------------------------------------------------------------- figures
def _outline_at(bag: BagReader, topic: str, log_time: int, stamp: int,
                ns: str = 'fruit_outline') -> Any:
    """The fruit marker (namespace ``ns``) nearest ``stamp``, read around ``log_time``."""
    best = None
    window = 200_000_000
    for _raw, msg in bag.decoded_messages([topic], start=max(0, log_time - window),
                                          end=log_time + window):
        for marker in msg.markers:
            if marker.ns == ns and marker.points:
                dist = abs(_stamp_ns(marker.header) - stamp)
                if best is None or dist < best[0]:
                    best = (dist, marker)
    return best[1] if best is not None else None


def _jaws_at(bag: BagReader, topic: str, log_time: int, stamp: int) -> list:
    """The ``jaws`` CUBE markers of the marker array whose stamp is nearest ``stamp``."""
    best = None
    window = 200_000_000
    for _raw, msg in bag.decoded_messages([topic], start=max(0, log_time - window),
                                          end=log_time + window):
        jaws = [m for m in msg.markers if m.ns == 'jaws' and int(m.type) == 1]  # CUBE
        if jaws:
            dist = abs(_stamp_ns(jaws[0].header) - stamp)
            if best is None or dist < best[0]:
                best = (dist, jaws)
    return best[1] if best is not None else []


def _jaw_face(marker: Any, centre_x: float) -> np.ndarray:
    """(4, 3) m: corners of a jaw cube's face towards ``centre_x`` (a y-z rectangle)."""
    p, size = marker.pose.position, marker.scale
    x = p.x - np.sign(p.x - centre_x) * 0.5 * size.x
    dy, dz = 0.5 * size.y, 0.5 * size.z
    return np.array([[x, p.y - dy, p.z - dz], [x, p.y + dy, p.z - dz],
                     [x, p.y + dy, p.z + dz], [x, p.y - dy, p.z + dz]])


def cloud_array(msg: Any) -> np.ndarray:
    """(n, 6) x y z fx fy fz (m, N) of a decoded node ``PointCloud2`` (float32 fields)."""
    names = ('x', 'y', 'z', 'fx', 'fy', 'fz')
    offsets = {f.name: int(f.offset) for f in msg.fields if int(f.datatype) == 7}  # FLOAT32
    if any(name not in offsets for name in names):
        raise RecordingError(f"the node cloud has fields {sorted(offsets)}, not {names}")
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    rows = raw[:n * step].reshape(n, step)
    order = '>f4' if msg.is_bigendian else '<f4'
    return np.column_stack([rows[:, offsets[name]:offsets[name] + 4].copy().view(order)[:, 0]
                            for name in names]).astype(float)


def _cloud_at(bag: BagReader, topic: str, log_time: int, stamp: int) -> np.ndarray | None:
    """The node cloud (``cloud_array``) with the header stamp nearest ``stamp``."""
    best = None
    window = 200_000_000
    for _raw, msg in bag.decoded_messages([topic], start=max(0, log_time - window),
                                          end=log_time + window):
        dist = abs(_stamp_ns(msg.header) - stamp)
        if best is None or dist < best[0]:
            best = (dist, msg)
    return cloud_array(best[1]) if best is not None else None


def jaw_contact_nodes(cloud: np.ndarray) -> dict[str, np.ndarray]:
    """Indices of the cloud's nodes pressed by the left and the right jaw.

    A node with a contact force f touches a jaw when the closing-axis component
    dominates, |f_x| > |f_z| (the table pushes along z; a jaw's friction is below its
    normal force for every friction coefficient below 1), the left jaw when f_x > 0
    (it pushes the fruit towards +x). Made for flat jaws: a V-groove flank tilts its
    normal in x-z by (90 deg - half the groove angle), and at 45 deg or more its nodes
    are not counted.
    """
    force = cloud[:, 3:6]
    touching = np.linalg.norm(force, axis=1) > 0
    jaw = touching & (np.abs(force[:, 0]) > np.abs(force[:, 2]))
    return {'left': np.flatnonzero(jaw & (force[:, 0] > 0)),
            'right': np.flatnonzero(jaw & (force[:, 0] < 0))}


def patch_outline(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Outline (closed, (k + 1, 2)) and area (m^2) of (n, 2) patch points (y, z): their
    convex hull; for fewer than 3 points (or collinear ones) the points and area 0."""
    if len(points) < 3:
        return np.asarray(points, dtype=float), 0.0
    from scipy.spatial import ConvexHull, QhullError
    try:
        hull = ConvexHull(points)
    except QhullError:
        return np.asarray(points, dtype=float), 0.0
    loop = points[np.append(hull.vertices, hull.vertices[0])]
    return loop, float(hull.volume)  # a 2D hull's "volume" is its area


def key_moments(series: TimeSeries) -> list[tuple[str, int]]:
    """(label, row) of the start, first grip, peak force and end."""
    both = (series['left_jaw_contact'] > 0) & (series['right_jaw_contact'] > 0)
    moments = [('start', 0)]
    if np.any(both):
        moments.append(('first grip', int(np.argmax(both))))
    moments.append(('peak force', int(np.argmax(series['grip_force_n']))))
    moments.append(('end', len(series) - 1))
    seen: set[int] = set()
    unique = []
    for label, row in moments:
        if row not in seen:
            seen.add(row)
            unique.append((label, row))
    return unique


def plot_force_vs_time(series: TimeSeries, summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    t = series['time_s']
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 6), dpi=110)
    ax1.plot(t, series['grip_force_n'], color='k', lw=1.6, label='grip force (mean)')
    if np.any(np.isfinite(series['left_force_n'])):
        ax1.plot(t, series['left_force_n'], lw=1, ls='--', label='left jaw')
    if np.any(np.isfinite(series['right_force_n'])):
        ax1.plot(t, series['right_force_n'], lw=1, ls=':', label='right jaw')
    ax1.plot([summary['time_of_peak_force_s']], [summary['peak_grip_force_n']], 'o',
             color='tab:red', label=f"peak {summary['peak_grip_force_n']:.2f} N")
    ax1.set_ylabel('normal force (N)')
    ax1.set_title('Grip force')
    ax1.grid(alpha=0.3)
    ax1.legend(loc='best', fontsize=8)
    ax2.plot(t, 1e3 * series['gap_m'], label='jaw gap')
    ax2.plot(t, 1e3 * series['compression_m'], label='compression')
    ax2.plot(t, 1e3 * series['slip_distance_m'], label='slip')
    ax2.set_xlabel('sim time (s)')
    ax2.set_ylabel('mm')
    ax2.grid(alpha=0.3)
    ax2.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_force_vs_compression(series: TimeSeries, summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 5), dpi=110)
    sc = ax.scatter(1e3 * series['compression_m'], series['grip_force_n'],
                    c=series['time_s'], s=6, cmap='viridis')
    fig.colorbar(sc, ax=ax, label='sim time (s)')
    x, y = loading_curve(series)
    k = summary['stiffness_n_per_m']
    if k is not None and x.size:
        upper = y >= 0.2 * y.max()
        xs = np.linspace(x[upper].min(), x[upper].max(), 20)
        b = float(np.mean(y[upper] - k * x[upper]))
        ax.plot(1e3 * xs, k * xs + b, 'r-', lw=1.5,
                label=f'tangent stiffness {k / 1e3:.2f} N/mm')
        ax.legend(loc='upper left', fontsize=8)
    ax.set_xlabel('compression (mm)')
    ax.set_ylabel('grip force (N)')
    ax.set_title('Force vs compression')
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _segment_strain(points: np.ndarray, rest: np.ndarray | None) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    if rest is None or rest.shape != seg.shape:
        return np.zeros_like(seg)
    with np.errstate(divide='ignore', invalid='ignore'):
        strain = np.where(rest > 0, seg / rest - 1.0, 0.0)
    return strain


def plot_outlines(bag: BagReader, topic: str, series: TimeSeries, summary: dict,
                  path: Path) -> bool:
    """Outline snapshots coloured by strain (top) and contact pressure (bottom)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    moments = key_moments(series)
    outlines = []
    for label, row in moments:
        marker = _outline_at(bag, topic, int(series.log_times[row]), int(series.stamps[row]))
        if marker is not None:
            outlines.append((label, row, marker))
    if not outlines:
        return False
    rest_points = np.array([[p.x, p.z] for p in outlines[0][2].points])
    rest = np.linalg.norm(np.diff(rest_points, axis=0), axis=1)
    strains = []
    for _, _, marker in outlines:
        pts = np.array([[p.x, p.z] for p in marker.points])
        strains.append(_segment_strain(pts, rest))
    limit = max(1e-6, max(float(np.max(np.abs(s))) for s in strains))
    fig, axes = plt.subplots(2, len(outlines), figsize=(3.2 * len(outlines) + 1.2, 6.6),
                             dpi=110, squeeze=False, layout='constrained')
    all_pts = np.vstack([[[p.x, p.z] for p in m.points] for _, _, m in outlines])
    pad = 0.1 * float(np.ptp(all_pts, axis=0).max() or 0.01)
    lo, hi = all_pts.min(axis=0) - pad, all_pts.max(axis=0) + pad
    line_sets = None
    for col, ((label, row, marker), strain) in enumerate(zip(outlines, strains)):
        pts = np.array([[p.x, p.z] for p in marker.points]) * 1e3
        segments = np.stack([pts[:-1], pts[1:]], axis=1)
        ax = axes[0][col]
        line_sets = LineCollection(list(segments), cmap='coolwarm', linewidths=3)
        line_sets.set_array(strain)
        line_sets.set_clim(-limit, limit)
        ax.add_collection(line_sets)
        ax.set_title(f'{label}\nt = {series["time_s"][row]:.3f} s', fontsize=9)
        ax2 = axes[1][col]
        colours = [(c.r, c.g, c.b) for c in marker.colors] if marker.colors else None
        if colours and len(colours) == len(pts):
            seg_colours = colours[:-1]
            ax2.add_collection(LineCollection(list(segments), colors=seg_colours,
                                              linewidths=3))
        else:
            ax2.plot(pts[:, 0], pts[:, 1], color='tab:green', lw=3)
        ax2.set_title(f'peak p = {series["peak_contact_pressure_pa"][row] / 1e3:.0f} kPa',
                      fontsize=9)
        for a in (ax, ax2):
            a.set_xlim(lo[0] * 1e3, hi[0] * 1e3)
            a.set_ylim(lo[1] * 1e3, hi[1] * 1e3)
            a.set_aspect('equal')
            a.set_xlabel('x (mm)', fontsize=8)
            a.tick_params(labelsize=7)
        if col == 0:
            ax.set_ylabel('skin strain\nz (mm)', fontsize=9)
            ax2.set_ylabel('contact pressure\nz (mm)', fontsize=9)
    if line_sets is not None:
        fig.colorbar(line_sets, ax=list(axes[0]), label='skin segment strain', shrink=0.9)
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    # the node's marker colours: green at 0, yellow at half, red at the bruise pressure
    pressure_map = LinearSegmentedColormap.from_list(
        'bruise', [(0.2, 0.8, 0.2), (1.0, 0.8, 0.2), (1.0, 0.0, 0.2)])
    bruise_kpa = summary.get('bruise_threshold_pa', DEFAULT_BRUISE_PRESSURE) / 1e3
    fig.colorbar(ScalarMappable(Normalize(0.0, bruise_kpa), pressure_map),
                 ax=list(axes[1]), label='contact pressure (kPa)', shrink=0.9)
    fig.suptitle('Fruit outline at key moments', fontsize=11)
    fig.savefig(path)
    plt.close(fig)
    return True


def _pressure_colour_map():
    """The node's marker colours as a colormap: green at 0, yellow at half, red at the
    bruise pressure (``gripper_sim.ros.messages.pressure_colour``)."""
    from matplotlib.colors import LinearSegmentedColormap
    return LinearSegmentedColormap.from_list(
        'bruise', [(0.2, 0.8, 0.2), (1.0, 0.8, 0.2), (1.0, 0.0, 0.2)])


def plot_mesh_snapshots(bag: BagReader, topic: str, series: TimeSeries, summary: dict,
                        path: Path) -> bool:
    """The 3D skin (``fruit_mesh`` TRIANGLE_LIST marker) at the key moments, each
    triangle coloured by the mean marker colour of its corners (contact pressure)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    meshes = []
    for label, row in key_moments(series):
        marker = _outline_at(bag, topic, int(series.log_times[row]), int(series.stamps[row]),
                             ns='fruit_mesh')
        if marker is not None and len(marker.points) >= 3:
            meshes.append((label, row, marker))
    if not meshes:
        return False
    fig = plt.figure(figsize=(3.6 * len(meshes) + 1.0, 4.4), dpi=110)
    all_pts = np.vstack([[[p.x, p.y, p.z] for p in m.points] for _, _, m in meshes]) * 1e3
    centre = 0.5 * (all_pts.min(axis=0) + all_pts.max(axis=0))
    half = 0.55 * float(np.ptp(all_pts, axis=0).max() or 10.0)
    for col, (label, row, marker) in enumerate(meshes):
        pts = np.array([[p.x, p.y, p.z] for p in marker.points]) * 1e3
        n_tri = len(pts) // 3
        triangles = pts[:3 * n_tri].reshape(n_tri, 3, 3)
        ax = fig.add_subplot(1, len(meshes), col + 1, projection='3d')
        if len(marker.colors) == len(marker.points):
            rgb = np.array([[c.r, c.g, c.b] for c in marker.colors])[:3 * n_tri]
            faces = rgb.reshape(n_tri, 3, 3).mean(axis=1)
        else:
            faces = np.tile([0.2, 0.8, 0.2], (n_tri, 1))
        ax.add_collection3d(Poly3DCollection(list(triangles), facecolors=faces,
                                             edgecolors=(0, 0, 0, 0.15), linewidths=0.2))
        jaws = _jaws_at(bag, topic, int(series.log_times[row]), int(series.stamps[row]))
        centre_x = float(pts[:, 0].mean()) * 1e-3
        plates = [_jaw_face(jaw, centre_x) * 1e3 for jaw in jaws]
        if plates:  # the jaw faces, see-through
            ax.add_collection3d(Poly3DCollection(plates, facecolors=(0.4, 0.4, 0.5, 0.15),
                                                 edgecolors=(0.2, 0.2, 0.3, 0.8),
                                                 linewidths=0.8))
        for axis, (set_lim, name) in enumerate(((ax.set_xlim, 'x'), (ax.set_ylim, 'y'),
                                                (ax.set_zlim, 'z'))):
            set_lim(centre[axis] - half, centre[axis] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=18, azim=-60)
        ax.set_xlabel('x (mm)', fontsize=7)
        ax.set_ylabel('y (mm)', fontsize=7)
        ax.set_zlabel('z (mm)', fontsize=7)
        ax.tick_params(labelsize=6)
        ax.set_title(f'{label}, t = {series["time_s"][row]:.3f} s\n'
                     f'F = {series["grip_force_n"][row]:.2f} N, peak p = '
                     f'{series["peak_contact_pressure_pa"][row] / 1e3:.0f} kPa', fontsize=8)
    bruise_kpa = summary.get('bruise_threshold_pa', DEFAULT_BRUISE_PRESSURE) / 1e3
    fig.colorbar(ScalarMappable(Normalize(0.0, bruise_kpa), _pressure_colour_map()),
                 ax=fig.axes, label='contact pressure (kPa)', shrink=0.7)
    fig.suptitle('Deformed fruit skin and jaw faces at key moments (colour: contact '
                 'pressure)', fontsize=10)
    fig.savefig(path)
    plt.close(fig)
    return True


def plot_contact_patch(bag: BagReader, topic: str, series: TimeSeries, summary: dict,
                       path: Path) -> dict | None:
    """The jaw contact patches at peak force: the nodes with a jaw contact force
    (``jaw_contact_nodes``) projected onto the jaw plane y-z, coloured by their normal
    force, with their convex outline and its area. Returns the patch areas (m^2) and
    node counts per jaw, or None when no cloud is near the peak."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    row = int(np.argmax(series['grip_force_n']))
    cloud = _cloud_at(bag, topic, int(series.log_times[row]), int(series.stamps[row]))
    if cloud is None:
        return None
    sides = jaw_contact_nodes(cloud)
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.4), dpi=110, layout='constrained')
    patches: dict[str, Any] = {}
    picked = np.concatenate([sides['left'], sides['right']])
    f_max = float(np.abs(cloud[picked, 3]).max()) if picked.size else 1.0
    scatter = None
    for ax, side in zip(axes, ('left', 'right')):
        nodes = sides[side]
        yz = cloud[nodes][:, [1, 2]]
        outline, area = patch_outline(yz)
        patches[side] = {'nodes': int(nodes.size), 'hull_area_m2': area}
        if nodes.size:
            scatter = ax.scatter(1e3 * yz[:, 0], 1e3 * yz[:, 1], c=np.abs(cloud[nodes, 3]),
                                 cmap='viridis', vmin=0.0, vmax=f_max, s=28)
            if len(outline) > 3:
                ax.plot(1e3 * outline[:, 0], 1e3 * outline[:, 1], 'k-', lw=1)
            centre = yz.mean(axis=0)
            span = max(float(np.ptp(yz, axis=0).max()), 1e-3)
            ax.set_xlim(1e3 * (centre[0] - span), 1e3 * (centre[0] + span))
            ax.set_ylim(1e3 * (centre[1] - span), 1e3 * (centre[1] + span))
        else:
            ax.text(0.5, 0.5, 'no contact', ha='center', va='center',
                    transform=ax.transAxes)
        ax.set_aspect('equal')
        ax.set_xlabel('y (mm)')
        ax.set_ylabel('z (mm)')
        ax.grid(alpha=0.3)
        ax.set_title(f'{side} jaw: {nodes.size} nodes, outline area {area * 1e6:.1f} mm^2',
                     fontsize=9)
    if scatter is not None:
        fig.colorbar(scatter, ax=list(axes), label='node normal force |f_x| (N)', shrink=0.8)
    fig.suptitle(f'Contact patches at peak force ({series["grip_force_n"][row]:.2f} N, '
                 f't = {series["time_s"][row]:.3f} s); contact area (vertex areas, both '
                 f'jaws) {series["contact_area_m2"][row] * 1e6:.1f} mm^2', fontsize=9)
    fig.savefig(path)
    plt.close(fig)
    return patches


# ---------------------------------------------------------------------- entry point
def analyze(path: str | os.PathLike, output_dir: str | os.PathLike, *,
            namespace: str | None = None, figures: bool = True,
            slip_threshold: float = SLIP_THRESHOLD) -> AnalysisResult:
    """Analyse the grasp recorded in ``path``; write CSV, JSON and PNGs to ``output_dir``.

    Raises:
        RecordingError: bad file, no FruitState topic, or the output cannot be written.
    """
    out = Path(output_dir)
    with BagReader(path) as bag:
        topics = find_topics(bag, namespace)
        config = read_config(bag)
        bruise = float(config.get('fruit.bruise_pressure', DEFAULT_BRUISE_PRESSURE))
        series = read_time_series(bag, topics)
        summary = summarize(series, bruise_pressure=bruise, slip_threshold=slip_threshold)
        summary = {'file': str(Path(path)), 'fruit_state_topic': topics['state'],
                   'left_wrench_topic': topics['left'], 'right_wrench_topic': topics['right'],
                   'fruit': config.get('fruit.name'), **summary}
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise RecordingError(f'cannot create {out}: {err.strerror}') from err
        result = AnalysisResult(summary=summary, output_dir=out)
        csv_path = out / 'timeseries.csv'
        write_csv(series, csv_path)
        result.files.append(csv_path)
        json_path = out / 'summary.json'
        result.files.append(json_path)
        if figures:
            p = out / 'force_vs_time.png'
            plot_force_vs_time(series, summary, p)
            result.files.append(p)
            p = out / 'force_vs_compression.png'
            plot_force_vs_compression(series, summary, p)
            result.files.append(p)
            if series.dimension == 3:
                if topics['markers'] is not None:
                    p = out / 'mesh_snapshots.png'
                    if plot_mesh_snapshots(bag, topics['markers'], series, summary, p):
                        result.files.append(p)
                if topics['nodes'] is not None:
                    p = out / 'contact_patch.png'
                    patches = plot_contact_patch(bag, topics['nodes'], series, summary, p)
                    if patches is not None:
                        result.files.append(p)
                        summary['contact_patches_at_peak_force'] = patches
            elif topics['markers'] is not None:
                p = out / 'outline_snapshots.png'
                if plot_outlines(bag, topics['markers'], series, summary, p):
                    result.files.append(p)
        # last: the 3D contact patch figure adds its measured patches to the summary
        json_path.write_text(json.dumps(summary, indent=2) + '\n', encoding='utf-8')
    return result


def load_summary(output_dir: str | os.PathLike) -> dict:
    """Read back a ``summary.json``."""
    return json.loads((Path(output_dir) / 'summary.json').read_text(encoding='utf-8'))


def iter_columns() -> Iterable[str]:
    return iter(COLUMNS)
