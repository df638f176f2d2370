"""Compiled 2D collision search of the barrier (``core.barrier``): its edge-vertex
candidates (broad phase) and the largest collision-free fraction of a step (CCD).

- Candidates: every (edge, vertex) pair whose boxes, each inflated by ``radius``, meet:
  the box of the vertex (or of the segment it sweeps from ``v0`` to ``v1``) and of the
  edge (its ends at both times). Sort and sweep along x: the vertices sorted by their
  boxes' low x, each edge scanning those whose low x lies in its box's x range widened
  by the widest vertex box. A vertex never pairs with its own edge, and a pair is kept
  only if the vertex may collide with either end (``groups``: one group per vertex,
  pairs across groups, or within one for a self-contact).
- Step bound: additive CCD (Li, Kaufman and Jiang 2021, "Codimensional Incremental
  Potential Contact", ACM Trans. Graph. 40(4) 170, Algorithm 1) of each point-segment
  candidate along straight paths: advance by the largest time the distance cannot
  close in, (1 - s) d0 / l_p first, then 0.9 d / l_p (l_p the bound on the relative
  speed of the pair after removing their mean motion), stopping before the distance
  falls below s d0; the bound is conservative (never at or past a crossing).
- Clear paths (a start of step's check): the same advance, stopping below s min(d0,
  d1), d1 the pair's distance at the end: a path that closes a gap to a small
  fraction of its start and no further (a node pushed ahead of a face) is cleared,
  which the step bound's floor s d0 would stop.
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: the step bound leaves each pair at least this fraction of its start distance
#: (as ipctk's CCD stops at 0.8 of the time of impact)
SEPARATION = 0.2
#: advances of one pair's CCD before it settles for the time it has reached
#: (conservative; only a pair sliding a long way at a tiny gap gets near it)
CCD_MAX_ADVANCES = 100000


@njit(cache=True)
def _may_collide(vertex, a, b, groups, same_group):
    if vertex == a or vertex == b:
        return False
    if same_group:
        return groups[vertex] == groups[a] or groups[vertex] == groups[b]
    return groups[vertex] != groups[a] or groups[vertex] != groups[b]


@njit(cache=True)
def _group_may_collide(group, group_a, group_b, same_group):
    """Whether a vertex of ``group`` may pair with an edge whose ends lie in ``group_a``
    and ``group_b`` (``_may_collide``'s rule on the groups alone)."""
    if same_group:
        return group == group_a or group == group_b
    return group != group_a or group != group_b


@njit(cache=True)
def edge_vertex_candidates(v0, v1, edges, groups, same_group, radius):
    """(k, 2) the (edge, vertex) pairs whose boxes inflated by ``radius`` (m) meet, each
    edge's in the order of its vertices' boxes' low x (ties as ``np.argsort`` orders them).

    Args:
        v0, v1: (n_m, 2) m, the collision mesh's vertices at the start and end of the
            motion (the same array for a static search).
        edges: (n_e, 2) the mesh's edges.
        groups: (n_m,) each vertex's group (0, 1, ...).  same_group: pairs within a group
            (a self-contact) instead of across groups.

    Each edge scans, in each group its vertices may pair with, the vertices whose low x
    lies in its box's x range widened by the widest vertex box (each group's vertices
    kept in the order of all of them): a fruit's edge scans the other bodies' vertices
    only, not its own.
    """
    n_v = v0.shape[0]
    low = np.empty((n_v, 2))
    high = np.empty((n_v, 2))
    widest = 0.0
    n_groups = 0
    for i in range(n_v):
        for c in range(2):
            low[i, c] = min(v0[i, c], v1[i, c]) - radius
            high[i, c] = max(v0[i, c], v1[i, c]) + radius
        widest = max(widest, high[i, 0] - low[i, 0])
        n_groups = max(n_groups, groups[i] + 1)
    order = np.argsort(low[:, 0])
    # each group's vertices in that order: members[group_start[g]:group_start[g + 1]]
    group_start = np.zeros(n_groups + 1, np.int64)
    for i in range(n_v):
        group_start[groups[i] + 1] += 1
    for g in range(n_groups):
        group_start[g + 1] += group_start[g]
    filled = group_start[:n_groups].copy()
    members = np.empty(n_v, np.int64)
    member_low = np.empty(n_v)
    rank = np.empty(n_v, np.int64)
    for k in range(n_v):
        i = order[k]
        g = groups[i]
        members[filled[g]] = i
        member_low[filled[g]] = low[i, 0]
        filled[g] += 1
        rank[i] = k
    capacity = 4 * (n_v + edges.shape[0]) + 16
    pairs = np.empty((capacity, 2), np.int64)
    count = 0
    found = np.empty(n_v, np.int64)  # one edge's vertices
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        e_low_x = min(low[a, 0], low[b, 0])
        e_high_x = max(high[a, 0], high[b, 0])
        e_low_y = min(low[a, 1], low[b, 1])
        e_high_y = max(high[a, 1], high[b, 1])
        m = 0
        sources = 0
        for g in range(n_groups):
            if not _group_may_collide(g, groups[a], groups[b], same_group):
                continue
            first, last = group_start[g], group_start[g + 1]
            before = m
            group_low = member_low[first:last]
            for k in range(first + np.searchsorted(group_low, e_low_x - widest),
                           first + np.searchsorted(group_low, e_high_x, side='right')):
                i = members[k]
                if (high[i, 0] < e_low_x or low[i, 0] > e_high_x or high[i, 1] < e_low_y
                        or low[i, 1] > e_high_y):
                    continue
                if not _may_collide(i, a, b, groups, same_group):
                    continue
                found[m] = i
                m += 1
            if m > before:
                sources += 1
        if sources > 1:  # several groups' vertices: in the order of all of them
            for j in range(1, m):
                i = found[j]
                k = j
                while k > 0 and rank[found[k - 1]] > rank[i]:
                    found[k] = found[k - 1]
                    k -= 1
                found[k] = i
        if count + m > capacity:
            capacity = max(2 * capacity, count + m)
            grown = np.empty((capacity, 2), np.int64)
            grown[:count] = pairs[:count]
            pairs = grown
        for j in range(m):
            pairs[count, 0] = e
            pairs[count, 1] = found[j]
            count += 1
    return pairs[:count].copy()


@njit(cache=True)
def _point_segment_distance(px, py, ax, ay, bx, by):
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    t = 0.0
    if length2 > 0.0:
        t = min(max(((px - ax) * ex + (py - ay) * ey) / length2, 0.0), 1.0)
    dx, dy = px - ax - t * ex, py - ay - t * ey
    return np.sqrt(dx * dx + dy * dy)


@njit(cache=True)
def _additive_ccd(p, a, b, dp, da, db, limit, to_end):
    """The time in [0, limit] the point p and segment a-b (2,) may move along dp, da, db
    (2,) with their distance staying at least ``SEPARATION`` of the start's, or with
    ``to_end`` of the smaller of the start's and the end's (0 if that is 0)."""
    mx = (dp[0] + da[0] + db[0]) / 3.0
    my = (dp[1] + da[1] + db[1]) / 3.0
    dpx, dpy = dp[0] - mx, dp[1] - my
    dax, day = da[0] - mx, da[1] - my
    dbx, dby = db[0] - mx, db[1] - my
    reach = (np.sqrt(dpx * dpx + dpy * dpy)
             + max(np.sqrt(dax * dax + day * day), np.sqrt(dbx * dbx + dby * dby)))
    px, py, ax, ay, bx, by = p[0], p[1], a[0], a[1], b[0], b[1]
    distance = _point_segment_distance(px, py, ax, ay, bx, by)
    floor = SEPARATION * distance
    if to_end:
        floor = min(floor, SEPARATION * _point_segment_distance(
            px + dp[0], py + dp[1], ax + da[0], ay + da[1], bx + db[0], by + db[1]))
        if floor <= 0.0:
            return 0.0
    if reach == 0.0:
        return limit
    if distance <= 0.0:
        return 0.0
    t = 0.0
    advance = (1.0 - SEPARATION) * distance / reach
    for _ in range(CCD_MAX_ADVANCES):
        if to_end:  # the end itself is checked, not a point past it
            advance = min(advance, limit - t)
        px += advance * dpx
        py += advance * dpy
        ax += advance * dax
        ay += advance * day
        bx += advance * dbx
        by += advance * dby
        distance = _point_segment_distance(px, py, ax, ay, bx, by)
        if t > 0.0 and distance < floor:
            return t
        t += advance
        if t >= limit:
            return limit
        advance = 0.9 * distance / reach
    return t


@njit(cache=True)
def collision_free_step(v0, v1, edges, candidates):
    """The largest fraction (0, 1] of the straight motion from ``v0`` to ``v1`` (n_m, 2)
    m along which no candidate (edge, vertex) pair (k, 2) closes below ``SEPARATION``
    of its start distance (0 if one starts touching)."""
    return _bounded_step(v0, v1, edges, candidates, False)


@njit(cache=True)
def paths_clear(v0, v1, edges, candidates):
    """Whether along the straight motion from ``v0`` to ``v1`` (n_m, 2) m no candidate
    (edge, vertex) pair (k, 2) closes below ``SEPARATION`` of the smaller of its start
    and end distances: no crossing for certain (False: maybe one)."""
    return _bounded_step(v0, v1, edges, candidates, True) == 1.0


@njit(cache=True)
def _bounded_step(v0, v1, edges, candidates, to_end):
    """``collision_free_step``, or with ``to_end`` the floor of ``paths_clear``."""
    step = 1.0
    dp, da, db = np.empty(2), np.empty(2), np.empty(2)
    for k in range(candidates.shape[0]):
        e, i = candidates[k, 0], candidates[k, 1]
        a, b = edges[e, 0], edges[e, 1]
        for c in range(2):
            dp[c] = v1[i, c] - v0[i, c]
            da[c] = v1[a, c] - v0[a, c]
            db[c] = v1[b, c] - v0[b, c]
        step = _additive_ccd(v0[i], v0[a], v0[b], dp, da, db, step, to_end)
        if step == 0.0:
            break
    return step


@njit(cache=True)
def smallest_distance(v, edges, candidates, beyond):
    """m, the smallest point-segment distance of the (edge, vertex) ``candidates`` (k, 2)
    at the vertices ``v`` (n_m, 2), or ``beyond`` if none is nearer."""
    smallest = beyond
    for k in range(candidates.shape[0]):
        e, i = candidates[k, 0], candidates[k, 1]
        a, b = edges[e, 0], edges[e, 1]
        smallest = min(smallest, _point_segment_distance(v[i, 0], v[i, 1], v[a, 0], v[a, 1],
                                                         v[b, 0], v[b, 1]))
    return smallest
