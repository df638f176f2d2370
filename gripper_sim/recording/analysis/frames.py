"""The geometry of chosen moments of a run, from the recorded ``~/markers`` and node cloud.

A ``Frame`` holds the fruit (2D: the closed outline; 3D: the skin triangles), the contact
pressure at each of its points, the jaw plates, the deformable fingers' outlines (if any)
and the table, all in the world frame (m).

The pressure is the damage estimate's contact pressure the node colours the fruit marker
with (Hertz per node in 2D, normal force over vertex area in 3D), read back from the
marker colours by inverting ``gripper_sim.convert.messages.pressure_colour`` (green at 0,
yellow at half the bruise pressure, red at and above it): exact below the bruise
pressure, and "at or above it" where the colour is saturated.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.reader import BagReader
from gripper_sim.recording.analysis.series import TimeSeries, stamp_ns

#: marker namespaces of the fruit, and of the deformable fingers' outlines
OUTLINE_NS, MESH_NS, SOFT_FINGERS_NS = 'fruit_outline', 'fruit_mesh', 'soft_fingers'
CUBE, LINE_LIST = 1, 5


@dataclass(frozen=True)
class Box:
    """An axis-aligned box: centre (3,) m and full size (3,) m."""

    centre: np.ndarray
    size: np.ndarray

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low corner, high corner), (3,) m each."""
        return self.centre - 0.5 * self.size, self.centre + 0.5 * self.size


@dataclass
class Frame:
    """The scene at one row of a run.

    Attributes:
        row: the row of the run's series; time: s of sim time.
        points: (k, 3) m; 2D: the outline, closed (first point repeated at the end);
            3D: the skin's vertices.
        triangles: (m, 3) vertex indices of the skin (3D), None in 2D.
        pressure: (k,) Pa at each point (NaN when the marker has no colours).
        jaws: the jaw plates; table: the table top, or None.
        label: what the moment is (e.g. 'grip'), for titles.
        finger_lines: (s, 2, 3) m, the deformable fingers' outline segments (none for
            rigid fingers: (0, 2, 3)).
    """

    row: int
    time: float
    points: np.ndarray
    triangles: np.ndarray | None
    pressure: np.ndarray
    jaws: list[Box] = field(default_factory=list)
    table: Box | None = None
    label: str = ''
    finger_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))


def pressure_from_colours(rgb: np.ndarray, bruise_pressure: float) -> np.ndarray:
    """(k,) Pa of (k, 3) marker colours made by ``pressure_colour`` (module docstring)."""
    rgb = np.asarray(rgb, dtype=float).reshape(-1, 3)
    red, green = rgb[:, 0], rgb[:, 1]
    share = np.where(red < 0.9999, (red - 0.2) / 1.6, 1.0 - green / 1.6)
    return np.clip(share, 0.0, 1.0) * bruise_pressure


def _box(marker: Any) -> Box:
    p, s = marker.pose.position, marker.scale
    return Box(np.array([p.x, p.y, p.z], dtype=float), np.array([s.x, s.y, s.z], dtype=float))


def frame_of(markers: Any, row: int, time: float, bruise_pressure: float) -> Frame | None:
    """The ``Frame`` of a decoded ``MarkerArray``, or None without a fruit marker."""
    fruit = None
    jaws: list[Box] = []
    table = None
    finger_lines = np.zeros((0, 2, 3))
    for marker in markers.markers:
        if marker.ns in (OUTLINE_NS, MESH_NS) and marker.points:
            fruit = marker
        elif marker.ns == 'jaws' and int(marker.type) == CUBE:
            jaws.append(_box(marker))
        elif marker.ns == 'table' and int(marker.type) == CUBE:
            table = _box(marker)
        elif marker.ns == SOFT_FINGERS_NS and int(marker.type) == LINE_LIST:
            finger_lines = np.array([[p.x, p.y, p.z] for p in marker.points],
                                    dtype=float).reshape(-1, 2, 3)
    if fruit is None:
        return None
    points = np.array([[p.x, p.y, p.z] for p in fruit.points], dtype=float)
    if len(fruit.colors) == len(fruit.points):
        pressure = pressure_from_colours([[c.r, c.g, c.b] for c in fruit.colors],
                                         bruise_pressure)
    else:
        pressure = np.full(len(points), np.nan)
    triangles = None
    if fruit.ns == MESH_NS:
        corners = points[:3 * (len(points) // 3)]
        points, first, inverse = np.unique(corners, axis=0, return_index=True,
                                           return_inverse=True)
        pressure = pressure[first]
        triangles = np.asarray(inverse, dtype=int).reshape(-1, 3)
    return Frame(row=row, time=time, points=points, triangles=triangles, pressure=pressure,
                 jaws=jaws, table=table, finger_lines=finger_lines)


def read_frames(bag: BagReader, topic: str, series: TimeSeries, rows: list[int],
                bruise_pressure: float) -> list[Frame]:
    """The frames of ``rows`` of ``series``: for each, the marker array logged nearest
    its FruitState (one pass over the topic; only the chosen messages are decoded)."""
    if not rows:
        return []
    wanted = np.asarray(series.log_times[rows], dtype=np.int64)
    order = np.argsort(wanted)
    sorted_times = wanted[order]
    best: dict[int, tuple[int, bytes]] = {}
    margin = 200_000_000
    for raw in bag.messages([topic], start=max(0, int(sorted_times[0]) - margin),
                            end=int(sorted_times[-1]) + margin):
        at = int(np.searchsorted(sorted_times, raw.log_time))
        for k in (at - 1, at):
            if 0 <= k < len(sorted_times):
                dist = abs(int(sorted_times[k]) - raw.log_time)
                if k not in best or dist < best[k][0]:
                    best[k] = (dist, raw.data)
    decode = bag.decoder(topic)
    frames: list[Frame] = []
    for k in range(len(sorted_times)):
        if k not in best:
            continue
        row = int(rows[int(order[k])])
        frame = frame_of(decode(best[k][1]), row, float(series['time_s'][row]),
                         bruise_pressure)
        if frame is not None:
            frames.append(frame)
    frames.sort(key=lambda f: f.row)
    return frames


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


def cloud_at(bag: BagReader, topic: str, log_time: int, stamp: int) -> np.ndarray | None:
    """The node cloud (``cloud_array``) with the header stamp nearest ``stamp``, among
    the messages logged within 0.2 s of ``log_time``."""
    best = None
    window = 200_000_000
    for _raw, msg in bag.decoded_messages([topic], start=max(0, log_time - window),
                                          end=log_time + window):
        dist = abs(stamp_ns(msg.header) - stamp)
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
    try:
        hull = ConvexHull(points)
    except QhullError:
        return np.asarray(points, dtype=float), 0.0
    loop = points[np.append(hull.vertices, hull.vertices[0])]
    return loop, float(hull.volume)  # a 2D hull's "volume" is its area
