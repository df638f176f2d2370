"""Deformation measures of the fruit from its node positions and contact forces.

The measures are compiled functions on arrays (``@njit``), called by the generic route
(``deformation``, ``face_contact_length``, ``tributary_lengths`` below) and by the
compiled step (``kernels.step_measures``): each measure is written once.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gripper_sim.core.barrier_kernels import mean_gap, normal_components
from gripper_sim.core.contact import jaw_sides
from gripper_sim.core.deferred import build
from gripper_sim.core.fruit import FruitModel
from gripper_sim.core.results import Deformation


# ---------------------------------------------------------------------- compiled measures
#: numpy's pairwise summation: a block of up to this many values is added in 8 partial sums
_PAIRWISE_BLOCK = 128


@njit(cache=True)
def _block_sum(values, start, n):
    """The sum of values[start:start + n], n <= 128, in numpy's order: a running sum of
    fewer than 8, else 8 partial sums combined pairwise, then the rest added."""
    if n < 8:
        total = 0.0
        for i in range(start, start + n):
            total += values[i]
        return total
    r0, r1, r2, r3 = values[start], values[start + 1], values[start + 2], values[start + 3]
    r4, r5, r6, r7 = values[start + 4], values[start + 5], values[start + 6], values[start + 7]
    i = 8
    while i < n - n % 8:
        j = start + i
        r0 += values[j]
        r1 += values[j + 1]
        r2 += values[j + 2]
        r3 += values[j + 3]
        r4 += values[j + 4]
        r5 += values[j + 5]
        r6 += values[j + 6]
        r7 += values[j + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        total += values[start + i]
        i += 1
    return total


@njit(cache=True)
def _pairwise(values, n):
    """The sum of values[:n] in numpy's pairwise order: a block (``_block_sum``) up to
    ``_PAIRWISE_BLOCK`` values, else the sum of its two halves (the first a multiple of
    8 long), each summed so in turn (an explicit stack: numba caches no recursion)."""
    if n <= _PAIRWISE_BLOCK:
        return _block_sum(values, 0, n)
    depth = 64
    starts, sizes = np.empty(depth, np.int64), np.empty(depth, np.int64)
    stages, lefts = np.zeros(depth, np.int64), np.empty(depth)
    top = 0
    starts[0], sizes[0] = 0, n
    result = 0.0  # the sum of the range last finished
    while top >= 0:
        start, size = starts[top], sizes[top]
        half = size // 2
        half -= half % 8
        if size <= _PAIRWISE_BLOCK:
            result = _block_sum(values, start, size)
            top -= 1
        elif stages[top] == 0:  # its first half next
            stages[top] = 1
            top += 1
            starts[top], sizes[top], stages[top] = start, half, 0
        elif stages[top] == 1:  # its first half done: its second half next
            lefts[top] = result
            stages[top] = 2
            top += 1
            starts[top], sizes[top], stages[top] = start + half, size - half, 0
        else:  # both halves done
            result = lefts[top] + result
            top -= 1
    return result


@njit(cache=True)
def numpy_sum(values, count):
    """The sum of values[:count] (float64) added as ``np.sum`` adds a contiguous array
    (pairwise: 8 partial sums over blocks of up to 128 values, halves beyond; onto 0), so
    that a compiled measure equals numpy's to the bit."""
    return 0.0 + _pairwise(values, count)


@njit(cache=True)
def jaw_normal_forces(obstacle, forces, normals, side_of_obstacle, left, right, normal,
                      scratch):
    """Each node's normal contact force (``normal_components``), the nodes each jaw holds
    (``contact.jaw_sides``) and each jaw's summed normal force, in one call.

    Args:
        obstacle: (n,) the obstacle holding each node, -1 none.  forces: (n, d) N, the
        contact force on each node.  normals: (k, d) the obstacles' unit normals.
        side_of_obstacle: (k + 1,) each obstacle's jaw side (0 left, 1 right, -1 none),
        and last -1 (no obstacle).  left, right: (n,) bool, the nodes the left and the
        right jaw hold (written).  normal: (n,) N, each held node's force along its
        obstacle's normal, 0 where free (written).  scratch: (n,) float.

    Returns:
        (whether the left jaw holds any node, the right, the left jaw's normal force N,
        the right's): each sum the one numpy gives ``normal[left].sum()`` to the bit
        (``numpy_sum``).
    """
    normal[:] = 0.0
    normal_components(obstacle, forces, normals, normal)
    any_left, any_right = jaw_sides(obstacle, side_of_obstacle, left, right)
    sums = np.zeros(2)
    for side, on in enumerate((left, right)):
        count = 0
        for i in range(normal.shape[0]):
            if on[i]:
                scratch[count] = normal[i]
                count += 1
        sums[side] = numpy_sum(scratch, count)
    return any_left, any_right, sums[0], sums[1]


@njit(cache=True, error_model='numpy')
def held_length_of(x, skin_edges, surface, held, lengths):
    """m, the sum (``numpy_sum``) of the tributary lengths (``tributary_lengths_of``) of
    the outline nodes ``surface`` (n_s,) held (``held`` (n,) bool) at positions ``x``
    (n, 2) m; ``lengths`` (n_s,) m scratch."""
    n_s = surface.shape[0]
    tributary_lengths_of(x, skin_edges, n_s, lengths)
    count = 0
    for s in range(n_s):
        if held[surface[s]]:
            lengths[count] = lengths[s]
            count += 1
    return numpy_sum(lengths, count)


@njit(cache=True, error_model='numpy')
def tributary_lengths_of(x, skin_edges, n_surface, out):
    """Fill ``out`` (n_surface,) m with half the length of the two skin segments at each
    outline node (0 without skin).

    Args:
        x: (n, 2) m.  skin_edges: (n_e, 2) int64, edge s from outline node s to s + 1
        (n_e = n_surface, or 0 for a fruit without skin).
    """
    n_e = skin_edges.shape[0]
    for s in range(n_surface):
        if n_e == 0:
            out[s] = 0.0
            continue
        i, j = skin_edges[s, 0], skin_edges[s, 1]
        seg = math.hypot(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1])
        k = (s - 1) % n_e
        i, j = skin_edges[k, 0], skin_edges[k, 1]
        prev = math.hypot(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1])
        out[s] = 0.5 * (seg + prev)


@njit(cache=True, error_model='numpy')
def outline_measures(x, surface, skin_edges, rest_segments, normal, depth, pressure_out):
    """The outline's width, largest skin strain and line contact pressures.

    Args:
        x: (n, 2) m.  surface: (n_s,) int64 outline nodes.  skin_edges: (n_e, 2) int64
        (see ``tributary_lengths_of``).  rest_segments: (n_e,) m, their rest lengths.
        normal: (n,) N, each node's normal contact force.  depth: m, out-of-plane b.
        pressure_out: (n_s,) Pa, output: each outline node's force over its tributary
        length and b (0 where the length is 0).

    Returns:
        (width m (extent along x), the skin strain of largest magnitude, the largest
        line contact pressure Pa).
    """
    ns = surface.shape[0]
    lo = np.inf
    hi = -np.inf
    for s in range(ns):
        lo = min(lo, x[surface[s], 0])
        hi = max(hi, x[surface[s], 0])
    best = 0.0
    strain_max = 0.0
    for e in range(skin_edges.shape[0]):
        i, j = skin_edges[e, 0], skin_edges[e, 1]
        strain = math.hypot(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1]) / rest_segments[e] - 1.0
        if e == 0 or abs(strain) > best:
            best = abs(strain)
            strain_max = strain
    tributary_lengths_of(x, skin_edges, ns, pressure_out)
    peak = 0.0
    for s in range(ns):
        trib = pressure_out[s]
        p = 0.0
        if trib > 0:
            p = max(normal[surface[s]], 0.0) / (trib * depth)
        pressure_out[s] = p
        peak = max(peak, p)
    return hi - lo, strain_max, peak


@njit(cache=True, error_model='numpy')
def separation_offset(x, ring, start, step, nx, nz, ox, oz):
    """Distance (m) along a face from the last contact node to where the outline leaves it.

    The gap of the free outline just past the contact edge grows like s^2 (a smooth
    surface leaving a flat face tangentially); the next two free nodes fix where it is
    zero. Falls back to half the segment when their gaps do not fit that.

    Args:
        x: (n, 2) m.  ring: (n_s,) outline nodes.  start: the outline position of the
        last contact node.  step: +1 or -1, the direction of the free nodes.
        nx, nz: the face's unit normal.  ox, oz: m, a point of the face.
    """
    n = ring.shape[0]
    node0 = ring[start % n]
    f1 = ring[(start + step) % n]
    f2 = ring[(start + 2 * step) % n]
    g1 = (x[f1, 0] - ox) * nx + (x[f1, 1] - oz) * nz
    g2 = (x[f2, 0] - ox) * nx + (x[f2, 1] - oz) * nz
    tx, tz = -nz, nx
    h0 = abs((x[f1, 0] - x[node0, 0]) * tx + (x[f1, 1] - x[node0, 1]) * tz)
    h1 = abs((x[f2, 0] - x[f1, 0]) * tx + (x[f2, 1] - x[f1, 1]) * tz)
    if g1 <= 0 or g2 <= g1 or h1 <= 0:
        return 0.5 * h0
    s1 = h1 / (math.sqrt(g2 / g1) - 1.0)
    return min(max(h0 - s1, 0.0), h0)


@njit(cache=True, error_model='numpy')
def face_contact_length_of(x, ring, holder, face, nx, nz, ox, oz):
    """Length (m) of the outline lying on a flat face: the span of the outline nodes it
    holds along the face, extended at each end to where the outline leaves it
    (``separation_offset``); 0 for an outline of fewer than 5 nodes.

    Args:
        x: (n, 2) m.  ring: (n_s,) outline nodes.  holder: (n,) int64, the face holding
        each node.  face: the face's index in ``holder``.  nx, nz: its unit normal.
        ox, oz: m, a point of it.
    """
    n = ring.shape[0]
    if n < 5:
        return 0.0
    tx, tz = -nz, nx
    top = np.int64(-1)  # not literals: one compiled separation_offset
    bottom = np.int64(-1)
    a_top = 0.0
    a_bottom = 0.0
    for r in range(n):
        i = ring[r]
        if holder[i] != face:
            continue
        along = x[i, 0] * tx + x[i, 1] * tz
        if top < 0 or along > a_top:
            top, a_top = r, along
        if bottom < 0 or along < a_bottom:
            bottom, a_bottom = r, along
    if top < 0:
        return 0.0
    length = a_top - a_bottom
    forward, backward = np.int64(1), np.int64(-1)
    for k in range(2):
        end = top if k == 0 else bottom
        if holder[ring[(end + 1) % n]] != face:
            length += separation_offset(x, ring, end, forward, nx, nz, ox, oz)
        elif holder[ring[(end - 1) % n]] != face:
            length += separation_offset(x, ring, end, backward, nx, nz, ox, oz)
    return length


@njit(cache=True, error_model='numpy')
def faces_contact_length_of(x, ring, holder, origins, normals, lifted):
    """m, the summed ``face_contact_length_of`` of k flat faces (face k the holder's k: its
    point ``origins[k]`` and unit normal ``normals[k]`` (k, 2)), each taken out along its
    normal by the mean gap of the nodes it holds (``barrier_kernels.mean_gap``) if
    ``lifted`` (the barrier model's outline lies a gap off its faces)."""
    length = 0.0
    for k in range(origins.shape[0]):
        offset = mean_gap(x, holder, k, origins[k], normals[k]) if lifted else 0.0
        nx, nz = normals[k, 0], normals[k, 1]
        length += face_contact_length_of(x, ring, holder, k, nx, nz,
                                         origins[k, 0] + offset * nx,
                                         origins[k, 1] + offset * nz)
    return length


# ---------------------------------------------------------------------- on a fruit model
def _skin(fruit: FruitModel) -> np.ndarray:
    """(n_e, 2) int64, the fruit's skin edges as the compiled measures take them."""
    return np.ascontiguousarray(fruit.skin_edges, dtype=np.int64).reshape(-1, 2)


#: the last fruit's (fruit, surface (n_s,), skin edges (n_e, 2), their rest lengths (n_e,)
#: m), ``outline_at_rest``'s
_kept_outline: tuple | None = None


def outline_at_rest(fruit: FruitModel) -> tuple:
    """(surface (n_s,) int64, skin edges (n_e, 2) int64, their rest lengths (n_e,) m) of
    ``fruit`` as the compiled measures take them; kept for the last fruit asked."""
    global _kept_outline
    kept = _kept_outline
    if kept is None or kept[0] is not fruit:
        skin = _skin(fruit)
        rest = fruit.rest_positions
        segments = np.hypot(*(rest[skin[:, 1]] - rest[skin[:, 0]]).T)
        kept = _kept_outline = (fruit, np.ascontiguousarray(fruit.surface, np.int64), skin,
                                np.ascontiguousarray(segments))
    return kept[1:]


def tributary_lengths(fruit: FruitModel, x: np.ndarray) -> np.ndarray:
    """(n_surface,) m, half the length of the two skin segments at each surface node."""
    surface, skin, _ = outline_at_rest(fruit)
    out = np.empty(len(surface))
    tributary_lengths_of(np.ascontiguousarray(x, dtype=float), skin, len(out), out)
    return out


def held_length(fruit: FruitModel, x: np.ndarray, held: np.ndarray) -> float:
    """m, the summed tributary lengths (``tributary_lengths``) of the surface nodes held
    (``held`` (n_nodes,) bool) at positions ``x`` (n_nodes, 2) m."""
    surface, skin, _ = outline_at_rest(fruit)
    return float(held_length_of(np.ascontiguousarray(x, dtype=float), skin, surface, held,
                                np.empty(len(surface))))


def touching_length(x: np.ndarray, edges: np.ndarray, touching: np.ndarray) -> float:
    """m, the length of an outline in contact: each edge (e, 2) of positions ``x`` (n, 2)
    counts by the share of its two ends that touch (``touching`` (n,) bool)."""
    seg = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1)
    return float(np.sum(seg * 0.5 * touching[edges].sum(axis=1)))


def face_contact_length(fruit: FruitModel, x: np.ndarray, face, holder: np.ndarray,
                        index: int, offset: float = 0.0) -> float:
    """Length (m) of the fruit outline lying on a flat face (``face_contact_length_of``).

    Args:
        x: (n_nodes, 2) m.  face: a FlatFace.  holder: (n_nodes,) int, the obstacle
        holding each node (-1 none).  index: the face's obstacle index in ``holder``.
        offset: m, the face taken this far out along its normal (the barrier's gap).
    """
    nx, nz = float(face.normal[0]), float(face.normal[1])
    return face_contact_length_of(
        np.ascontiguousarray(x, dtype=float), outline_at_rest(fruit)[0],
        np.ascontiguousarray(holder, np.int64), index, nx, nz,
        float(face.origin[0]) + offset * nx, float(face.origin[1]) + offset * nz)


def faces_contact_length(fruit: FruitModel, x: np.ndarray, faces: list, holder: np.ndarray,
                         lifted: bool) -> float:
    """m, the summed ``face_contact_length`` of the flat ``faces`` (face k the obstacle k of
    ``holder`` (n_nodes,)), at positions ``x`` (n_nodes, 2) m, each taken out by the mean
    gap of the nodes it holds if ``lifted`` (``faces_contact_length_of``)."""
    origins = np.array([face.origin for face in faces], dtype=float).reshape(-1, 2)
    normals = np.array([face.normal for face in faces], dtype=float).reshape(-1, 2)
    return float(faces_contact_length_of(
        np.ascontiguousarray(x, dtype=float), outline_at_rest(fruit)[0],
        np.ascontiguousarray(holder, np.int64), origins, normals, lifted))


def deformation(fruit: FruitModel, x: np.ndarray, normal_force: np.ndarray,
                jaw_contact: np.ndarray, jaw_contact_length: float | None = None) -> Deformation:
    """Measures at positions ``x`` (n_nodes, 2).

    Args:
        normal_force: (n_nodes,) N, normal contact reaction at each node (0 if free).
        jaw_contact: (n_nodes,) bool, node held by a jaw.
        jaw_contact_length: m, the contact length; None: the tributary length of the
            outline nodes the jaws hold.
    """
    x = np.ascontiguousarray(x, dtype=float)
    surface, skin, rest_segments = outline_at_rest(fruit)
    pressure = np.empty(len(surface))
    width, max_strain, peak = outline_measures(
        x, surface, skin, rest_segments,
        np.ascontiguousarray(normal_force, dtype=float), float(fruit.depth), pressure)
    if jaw_contact_length is None:
        jaw_contact_length = held_length(fruit, x, jaw_contact)
    return deformation_of(fruit, width, max_strain, peak, pressure, jaw_contact_length)


def deformation_of(fruit: FruitModel, width: float, max_strain: float, peak: float,
                   pressure: np.ndarray, contact_length: float) -> Deformation:
    """The ``Deformation`` of ``fruit`` from its outline's measures (``outline_measures``:
    the width m, the largest skin strain, the peak line pressure Pa, each outline node's
    pressure (n_s,) Pa) and the jaws' contact length m."""
    compression = fruit.rest_width - width
    ratio = compression / fruit.rest_width if fruit.rest_width > 0 else 0.0
    return build(Deformation, dict(compression=compression, compression_ratio=ratio,
                                   max_skin_strain=max_strain,
                                   contact_length=contact_length,
                                   peak_contact_pressure=peak, node_pressure=pressure))
