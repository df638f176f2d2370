"""Rest outlines of the fruit, counter-clockwise in the x-z plane, centred at the origin.

An outline is sampled at ``n`` nodes evenly spaced in arc length. Shapes
(``fruit.shape.type``):

- ``circle``: diameter D (node 0 at +x, on the right jaw's axis).
- ``ellipse``: x = (D/2) cos t, z = (H/2) sin t (D = ``fruit.shape.diameter``, H =
  ``fruit.shape.height``).
- ``egg``: a one-parameter ovoid, x = a cos t (1 - k sin t), z = b sin t, with k =
  ``fruit.shape.taper`` (0 = ellipse; the narrow end at +z), then scaled along x so that
  its largest width is D. (Our own simple form; see Narushin, Romanov & Griffin 2021,
  Ann. N.Y. Acad. Sci. 1505, for measured egg profiles.)
- ``points``: the closed polygon through ``fruit.shape.points`` ([x, z] pairs, m).
- ``spline``: the periodic cubic spline (scipy ``CubicSpline``, ``bc_type='periodic'``,
  chord-length parameter) through ``fruit.shape.points``.

Every shape is then rotated by ``fruit.shape.angle`` (degrees, counter-clockwise) about
its area centroid, which is put at the origin. An outline that crosses itself, has
coinciding points or no area raises ``ConfigError`` naming the key.
"""
from __future__ import annotations

import json
import math

import numpy as np

from gripper_sim.errors import ConfigError

#: dense samples per output node when a curve is resampled by arc length
OVERSAMPLING = 16


def circle(diameter: float, n: int) -> np.ndarray:
    """(n, 2) m, nodes on a circle, node 0 at +x (on the right jaw's axis)."""
    theta = 2 * np.pi * np.arange(n) / n
    return 0.5 * diameter * np.stack([np.cos(theta), np.sin(theta)], axis=1)


def resample_closed(points: np.ndarray, n: int) -> np.ndarray:
    """(n, 2) nodes evenly spaced in arc length along the closed polyline ``points``.

    The first node is ``points[0]``.
    """
    closed = np.vstack([points, points[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


def ellipse(width: float, height: float, n: int) -> np.ndarray:
    """(n, 2) m, an ellipse of axes ``width`` (x) and ``height`` (z), node 0 at +x."""
    t = 2 * np.pi * np.arange(OVERSAMPLING * n) / (OVERSAMPLING * n)
    dense = np.stack([0.5 * width * np.cos(t), 0.5 * height * np.sin(t)], axis=1)
    return resample_closed(dense, n)


def egg(width: float, height: float, taper: float, n: int) -> np.ndarray:
    """(n, 2) m, the ovoid x = a cos t (1 - k sin t), z = b sin t scaled to ``width``."""
    t = 2 * np.pi * np.arange(OVERSAMPLING * n) / (OVERSAMPLING * n)
    x = np.cos(t) * (1.0 - taper * np.sin(t))
    dense = np.stack([0.5 * width * x / np.max(np.abs(x)), 0.5 * height * np.sin(t)],
                     axis=1)
    return resample_closed(dense, n)


def periodic_spline(points: np.ndarray, n: int) -> np.ndarray:
    """(n, 2) m, the periodic cubic spline through ``points`` (m, 2), sampled evenly."""
    from scipy.interpolate import CubicSpline
    closed = np.vstack([points, points[:1]])
    chord = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    u = np.concatenate([[0.0], np.cumsum(chord)])
    spline = CubicSpline(u, closed, axis=0, bc_type='periodic')
    dense = spline(np.linspace(0.0, u[-1], OVERSAMPLING * max(n, 8 * len(points)),
                               endpoint=False))
    return resample_closed(dense, n)


def polygon_area(points: np.ndarray) -> float:
    """Signed shoelace area (m^2) of a closed polygon (n, 2); > 0 if counter-clockwise."""
    nxt = np.roll(points, -1, axis=0)
    return float(0.5 * np.sum(points[:, 0] * nxt[:, 1] - nxt[:, 0] * points[:, 1]))


def polygon_centroid(points: np.ndarray) -> np.ndarray:
    """(2,) m, area centroid of a closed polygon."""
    nxt = np.roll(points, -1, axis=0)
    cross = points[:, 0] * nxt[:, 1] - nxt[:, 0] * points[:, 1]
    area = 0.5 * np.sum(cross)
    return np.array([np.sum((points[:, 0] + nxt[:, 0]) * cross),
                     np.sum((points[:, 1] + nxt[:, 1]) * cross)]) / (6.0 * area)


def crossing_segments(points: np.ndarray) -> tuple[int, int] | None:
    """The first pair (i, j), i < j, of non-adjacent edges of the closed polygon that
    intersect.

    Edge i joins ``points[i]`` and ``points[i + 1]``. Touching counts as crossing.
    Returns None when the polygon is simple. Only pairs whose bounding boxes meet are
    tested (every crossing or touching pair's do), found by a sweep along x: with the
    edges sorted by their lowest x, an edge's x-overlapping successors are the run up to
    its highest x.
    """
    p = np.asarray(points, dtype=float)
    n = len(p)
    if n < 4:
        return None
    a, b = p, np.roll(p, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    scale = max(float(np.ptp(p)), 1e-300)
    eps = 1e-12 * scale * scale
    order = np.argsort(lo[:, 0], kind='stable')
    sorted_lo = lo[order, 0]
    ends = np.searchsorted(sorted_lo, hi[order, 0], side='right')
    counts = np.maximum(ends - np.arange(n) - 1, 0)
    found: list[tuple[int, int]] = []
    first = 0
    while first < n:                       # blocks of edges with at most ~2^20 pairs
        last = int(np.searchsorted(np.cumsum(counts[first:]), 1 << 20, side='right'))
        last = min(n, first + max(last, 1))
        rank = np.repeat(np.arange(first, last), counts[first:last])
        offset = np.arange(rank.size) - np.repeat(np.cumsum(counts[first:last])
                                                  - counts[first:last], counts[first:last])
        ei, ej = order[rank], order[rank + 1 + offset]
        ei, ej = np.minimum(ei, ej), np.maximum(ei, ej)
        keep = ((ej - ei >= 2) & ~((ei == 0) & (ej == n - 1))      # not neighbours
                & (lo[ei, 1] <= hi[ej, 1]) & (lo[ej, 1] <= hi[ei, 1]))
        ei, ej = ei[keep], ej[keep]
        hit = _intersect(a[ei], b[ei], a[ej], b[ej], eps)
        if np.any(hit):
            k = np.lexsort((ej[hit], ei[hit]))[0]
            found.append((int(ei[hit][k]), int(ej[hit][k])))
        first = last
    return min(found) if found else None


def _intersect(ai, bi, aj, bj, eps: float) -> np.ndarray:
    """(k,) whether segments ai-bi and aj-bj (each (k, 2)) cross or touch (an endpoint on
    the other segment within the orientation tolerance ``eps``, m^2)."""
    def orient(p0, p1, q):
        return ((p1[:, 0] - p0[:, 0]) * (q[:, 1] - p0[:, 1])
                - (p1[:, 1] - p0[:, 1]) * (q[:, 0] - p0[:, 0]))

    d1, d2 = orient(ai, bi, aj), orient(ai, bi, bj)
    d3, d4 = orient(aj, bj, ai), orient(aj, bj, bi)
    proper = (((d1 > eps) & (d2 < -eps)) | ((d1 < -eps) & (d2 > eps))) & \
             (((d3 > eps) & (d4 < -eps)) | ((d3 < -eps) & (d4 > eps)))
    touch = ((np.abs(d1) <= eps) & _within(ai, bi, aj)) | \
            ((np.abs(d2) <= eps) & _within(ai, bi, bj)) | \
            ((np.abs(d3) <= eps) & _within(aj, bj, ai)) | \
            ((np.abs(d4) <= eps) & _within(aj, bj, bi))
    return proper | touch


def _within(q0, q1, r) -> np.ndarray:
    """(k,) whether each point r (k, 2) lies inside the bounding box of its segment
    q0-q1 (k, 2)."""
    lo, hi = np.minimum(q0, q1), np.maximum(q0, q1)
    return np.all((r >= lo) & (r <= hi), axis=-1)


def parse_points(value, key: str = 'fruit.shape.points', pair: str = '[x, z]',
                 outline: bool = True) -> np.ndarray:
    """(m, 2) m from a list of ``pair`` pairs or its JSON/YAML text; ConfigError if not.
    An ``outline`` drops a closing repeat of its first point."""
    if isinstance(value, str):
        text = value.strip()
        if not text:
            raise ConfigError(f"config key '{key}' is empty: give a list of {pair} pairs "
                              'in metres')
        try:
            value = json.loads(text)
        except ValueError:
            import yaml
            try:
                value = yaml.safe_load(text)
            except yaml.YAMLError as err:
                raise ConfigError(f"config key '{key}' is not a list of {pair} pairs") \
                    from err
    try:
        points = np.array(value, dtype=float)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"config key '{key}' must be a list of {pair} number pairs") \
            from err
    if points.ndim != 2 or points.shape[1] != 2:
        raise ConfigError(f"config key '{key}' must be a list of {pair} number pairs")
    if not np.all(np.isfinite(points)):
        raise ConfigError(f"config key '{key}' holds a non-finite number")
    if outline and len(points) > 1 and np.allclose(points[0], points[-1], rtol=0,
                                                   atol=1e-12):
        points = points[:-1]  # a closing repeat of the first point
    return points


def _check_polygon(points: np.ndarray, key: str, what: str) -> None:
    seg = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    size = float(np.ptp(points))
    same = np.flatnonzero(seg <= 1e-9 * max(size, 1e-9))
    if same.size:
        i = int(same[0])
        raise ConfigError(f"config key '{key}': points {i} and {(i + 1) % len(points)} "
                          f'coincide')
    crossing = crossing_segments(points)
    if crossing is not None:
        i, j = crossing
        n = len(points)
        raise ConfigError(f"config key '{key}': the {what} crosses itself (segment "
                          f'{i}-{(i + 1) % n} meets segment {j}-{(j + 1) % n})')
    if abs(polygon_area(points)) <= 1e-6 * size * size:
        raise ConfigError(f"config key '{key}': the {what} encloses no area")


def _outline_points(config, n: int) -> np.ndarray:
    kind = config['fruit.shape.type']
    key = 'fruit.shape.points'
    points = parse_points(config[key], key)
    minimum = 3 if kind == 'points' else 4
    if len(points) < minimum:
        raise ConfigError(f"config key '{key}' needs at least {minimum} distinct points "
                          f'for a {kind} outline, got {len(points)}')
    _check_polygon(points, key, 'outline')
    if polygon_area(points) < 0:
        points = points[::-1].copy()  # the outline is used counter-clockwise
    if kind == 'points':
        return resample_closed(points, n)
    curve = periodic_spline(points, n)
    dense = periodic_spline(points, OVERSAMPLING * max(n, 8 * len(points)))
    _check_polygon(dense, key, 'spline through the points')
    return curve


def outline_from_config(config) -> np.ndarray:
    """The rest outline (n, 2) m that the configuration asks for.

    Raises:
        ConfigError: an unknown shape, an outline that crosses itself, has repeated
            points, no area, or a size outside 5 mm - 0.5 m.
    """
    kind = config['fruit.shape.type']
    n = int(config['fruit.nodes'])
    diameter = config['fruit.shape.diameter']
    height = config.get('fruit.shape.height')
    height = diameter if height is None else height
    if kind == 'circle':
        outline = circle(diameter, n)
    elif kind == 'ellipse':
        outline = ellipse(diameter, height, n)
    elif kind == 'egg':
        outline = egg(diameter, height, config.get('fruit.shape.taper', 0.15), n)
    elif kind in ('points', 'spline'):
        outline = _outline_points(config, n)
        size = float(max(np.ptp(outline[:, 0]), np.ptp(outline[:, 1])))
        if not 0.005 <= size <= 0.5:
            raise ConfigError(f"config key 'fruit.shape.points': the outline is {size:.4g} m "
                              'across; it must be 0.005-0.5 m (the points are in metres)')
    else:
        raise ConfigError(f"config key 'fruit.shape.type': unknown shape '{kind}'")
    angle = float(config.get('fruit.shape.angle', 0.0) or 0.0)
    if kind == 'circle' and angle == 0.0:
        return outline
    outline = outline - polygon_centroid(outline)
    if angle != 0.0:
        c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        outline = outline @ np.array([[c, s], [-s, c]])
    return outline


def equivalent_diameter(config, outline: np.ndarray) -> float:
    """m: the diameter of the circle of the outline's area (the circle's own diameter)."""
    if config['fruit.shape.type'] == 'circle':
        return float(config['fruit.shape.diameter'])
    return float(math.sqrt(4.0 * abs(polygon_area(outline)) / math.pi))
