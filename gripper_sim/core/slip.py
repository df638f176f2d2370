"""When a grasp slipped, how far the fruit slid, and when it is slipping: the one
definition of each.

``ContactSlide`` (how far the fruit slid down the jaws at its contacts) is the slip
measure of both grasp workflows, the pick (``workflows.grasp.GraspSequence``: ``pick``,
the node's Grasp action) and the pick-and-place (``workflows.scenario.PickAndPlace``:
``run``, ``window``, studies); ``grasp_slipped`` (the outcome) is shared by the pick and
the analysis of a recording (``analyze``); ``patches_sliding`` (``StepResult.slipping``,
``FruitState.slipping``) by both simulation facades and the 2D fast path, through
``jaw_contacts_sliding`` with rigid jaws and ``surface_motion`` with deformable fingers.
"""
from __future__ import annotations

import numpy as np
from numba import njit

#: slip (m) of the fruit relative to the jaws beyond which the grasp slipped
SLIP_TOLERANCE = 1e-3

#: m/s, speed along a jaw face, relative to it, above which a contact node slides (a
#: stuck node moves with its jaw; a soft pad's friction creeps below 1e-4 m/s)
SLIDING_SPEED = 1e-3
#: the fraction of a jaw's contact nodes that slide when the fruit slides in the jaws (all
#: of them, in gross slip): a patch a quarter or more of which sticks slips only partly
#: and holds (its rim in a squeeze, the upper part of a fruit that bulges up the jaws
#: squeezed on the table: half of the patch and more in 2D)
SLIDING_FRACTION = 0.75


def grasp_slipped(held_slip: float, dropped: bool = False) -> bool:
    """Whether a grasp slipped.

    Args:
        held_slip: m, the fruit's slip relative to the jaws from the lift-off (from the
            grip when there is no lift) to the end of the hold: for a pick the largest
            ``ContactSlide``; for a recording (``analyze``, which has no contact nodes)
            the centroid's drop at the end of the hold (``FruitState.slip_distance``).
            Pushes of one jaw before the grip and the fruit's motion during a release
            do not count.
        dropped: no jaw touched the fruit at some time between the lift-off (or the
            grip) and the end of the hold.
    """
    return bool(dropped) or held_slip > SLIP_TOLERANCE


def jaw_contacts_sliding(velocities: np.ndarray, holder: np.ndarray, jaw_of_face: np.ndarray,
                         face_normals: np.ndarray, face_velocities: np.ndarray,
                         positions: np.ndarray | None = None) -> bool:
    """Whether the fruit is slipping in jaws of rigid faces (``patches_sliding``).

    Args:
        velocities: (n_nodes, d) m/s, node velocities.
        holder: (n_nodes,) int, the obstacle (face) holding each node, -1 if none.
        jaw_of_face: (n_faces,) int, the jaw (0 left, 1 right) of each face, -1 for the
            faces of no jaw (table, walls).
        face_normals: (n_faces, d) unit normals.  face_velocities: (n_faces, d) m/s.
        positions: (n_nodes, 3) m, node positions (3D); None (2D).
    """
    if positions is None:
        return bool(_faces_nodes_sliding(velocities, holder, jaw_of_face, face_normals,
                                         face_velocities))
    held = np.flatnonzero(holder >= 0)
    face = holder[held]
    jaw = jaw_of_face[face]
    on_jaw = jaw >= 0
    if not np.any(on_jaw):
        return False
    held, face = held[on_jaw], face[on_jaw]
    return patches_sliding(velocities[held] - face_velocities[face], face_normals[face],
                           jaw[on_jaw], positions[held])


def patches_sliding(relative: np.ndarray, normals: np.ndarray, jaw: np.ndarray,
                    positions: np.ndarray | None = None) -> bool:
    """Whether the fruit is slipping in the jaws: on either jaw, more than
    ``SLIDING_FRACTION`` of the nodes it holds move along its surface faster than
    ``SLIDING_SPEED`` relative to it.

    Only the motion at the contacts counts: a fruit that deforms while every contact node
    sticks (it sags under its weight, bulges in a squeeze) is not slipping, nor one whose
    patches slip only partly: squeezed on the table, a 2D fruit bulges up the jaws, the
    upper half of each patch and more sliding up while the rest sticks.

    With ``positions`` (3D) a node moves at the contact patch's rigid motion relative to
    its jaw, not at its own: the translation along the surface and the spin about the
    closing axis (x) fitted (least squares) to the tangential relative velocities of the
    nodes the jaw holds. The rest is the patch's deformation, no sliding of the fruit:
    while a 3D patch grows in a squeeze its outer rings slip radially towards its centre
    and the centre sticks (partial slip, as of an elastic sphere pressed on a rigid flat
    with finite friction); on a 20 ms step those rings, new ones each step, are most of
    the patch's nodes, but their slip has no mean and no spin. A fruit that slides (down
    the jaws, or turning about the grip axis) moves its patches as a whole.

    Args:
        relative: (k, d) m/s, each held node's velocity relative to the surface holding
            it: a rigid face, or a deformable finger's surface where the node lies on it
            (``surface_motion``).
        normals: (k, d) unit normals of that surface.  jaw: (k,) 0 left, 1 right.
        positions: (k, 3) m, the nodes (3D); None (2D): each node at its own velocity.
    """
    if positions is None:
        return bool(_nodes_sliding(relative, normals, jaw))
    along = relative - np.sum(relative * normals, axis=1)[:, None] * normals
    held, sliding = np.zeros(2, np.int64), np.zeros(2, np.int64)
    for side in (0, 1):
        mine = jaw == side
        if np.any(mine):
            moving = _patch_motion(positions[mine], normals[mine], along[mine])
            held[side] = len(moving)
            sliding[side] = np.count_nonzero(np.sum(moving * moving, axis=1)
                                             > SLIDING_SPEED ** 2)
    return bool(_most_slide(held, sliding))


@njit(cache=True)
def _nodes_sliding(relative, normals, jaw):
    """``patches_sliding`` of each node at its own motion: ``relative``, ``normals``
    (k, d), ``jaw`` (k,)."""
    held, sliding = np.zeros(2, np.int64), np.zeros(2, np.int64)
    for i in range(jaw.shape[0]):
        held[jaw[i]] += 1
        sliding[jaw[i]] += _slides(relative[i], normals[i])
    return _most_slide(held, sliding)


@njit(cache=True)
def _faces_nodes_sliding(velocities, holder, jaw_of_face, face_normals, face_velocities):
    """``_nodes_sliding`` of the nodes held by jaw faces (``jaw_contacts_sliding``'s
    arguments), the nodes gathered here."""
    held, sliding = np.zeros(2, np.int64), np.zeros(2, np.int64)
    relative = np.empty(velocities.shape[1])
    for i in range(holder.shape[0]):
        face = holder[i]
        if face < 0 or jaw_of_face[face] < 0:
            continue
        relative[:] = velocities[i] - face_velocities[face]
        held[jaw_of_face[face]] += 1
        sliding[jaw_of_face[face]] += _slides(relative, face_normals[face])
    return _most_slide(held, sliding)


@njit(cache=True, inline='always')
def _slides(relative, normal):
    """1 if ``relative`` (d,) m/s has a part along the surface of unit ``normal`` (d,)
    faster than ``SLIDING_SPEED``, else 0."""
    along_normal = np.sum(relative * normal)
    tangential = 0.0
    for axis in range(relative.shape[0]):
        tangential += (relative[axis] - along_normal * normal[axis]) ** 2
    return 1 if tangential > SLIDING_SPEED ** 2 else 0


@njit(cache=True, inline='always')
def _most_slide(held, sliding):
    """Whether on either jaw more than ``SLIDING_FRACTION`` of the ``held`` (2,) nodes are
    ``sliding``."""
    return (sliding[0] > SLIDING_FRACTION * held[0]
            or sliding[1] > SLIDING_FRACTION * held[1])


def _patch_motion(x: np.ndarray, normals: np.ndarray, along: np.ndarray) -> np.ndarray:
    """(k, 3) m/s, the rigid motion of a jaw's contact patch at its k nodes: the velocity
    t + w (e_x cross r) (r from the patch's centroid) projected on each node's surface,
    fitted by least squares to their tangential relative velocities ``along`` (k, 3) m/s;
    ``x`` (k, 3) m the nodes, ``normals`` (k, 3) their surfaces' unit normals."""
    r = x - x.mean(axis=0)
    spin = np.zeros_like(r)  # e_x cross r
    spin[:, 1], spin[:, 2] = -r[:, 2], r[:, 1]
    tangential = np.eye(3) - normals[:, :, None] * normals[:, None, :]  # (k, 3, 3)
    columns = np.concatenate([tangential, (tangential @ spin[:, :, None])], axis=2)
    fit = np.linalg.lstsq(columns.reshape(-1, 4), along.ravel(), rcond=None)[0]
    return columns @ fit


@njit(cache=True)
def surface_motion(points, elements, positions, velocities):
    """The motion of a deformable surface where k ``points`` (k, d) m lie on it: at each
    point's nearest point of the surface, its velocity (k, d) m/s (linear over the
    element) and the element's unit normal (k, d) (either sign).

    Args:
        elements: the surface's (e, d) node indices into ``positions`` (N, d) m and
            ``velocities`` (N, d) m/s: edges in 2D, triangles in 3D.
    """
    k, d = points.shape
    velocity, normal = np.zeros((k, d)), np.zeros((k, d))
    weights, kept = np.empty(d), np.empty(d)
    for i in range(k):
        best, nearest = np.inf, -1
        for e in range(elements.shape[0]):
            if d == 2:
                _segment_weights(points[i], positions, elements[e], weights)
            else:
                _triangle_weights(points[i], positions, elements[e], weights)
            squared = 0.0
            for axis in range(d):
                at = 0.0
                for corner in range(d):
                    at += weights[corner] * positions[elements[e, corner], axis]
                squared += (at - points[i, axis]) ** 2
            if squared < best:
                best, nearest = squared, e
                kept[:] = weights
        for corner in range(d):
            velocity[i] += kept[corner] * velocities[elements[nearest, corner]]
        _unit_normal(positions, elements[nearest], normal[i])
    return velocity, normal


@njit(cache=True, inline='always')
def _segment_weights(p, positions, ends, weights):
    """``weights`` (2,) of the segment's ``ends`` giving its point nearest ``p`` (2,) m."""
    a, b = positions[ends[0]], positions[ends[1]]
    ex, ey = b[0] - a[0], b[1] - a[1]
    t = min(max(((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / (ex * ex + ey * ey), 0.0), 1.0)
    weights[0], weights[1] = 1.0 - t, t


@njit(cache=True, inline='always')
def _triangle_weights(p, positions, corners, weights):
    """``weights`` (3,): the barycentric coordinates on the triangle ``corners`` of the
    projection of ``p`` (3,) m on its plane, clipped to the triangle (negative ones
    dropped, the rest scaled to sum 1: the nearest point where the projection falls
    inside, near it elsewhere)."""
    a, b, c = positions[corners[0]], positions[corners[1]], positions[corners[2]]
    uu = uw = ww = ru = rw = 0.0
    for axis in range(3):
        u, w, r = b[axis] - a[axis], c[axis] - a[axis], p[axis] - a[axis]
        uu += u * u
        uw += u * w
        ww += w * w
        ru += r * u
        rw += r * w
    det = uu * ww - uw * uw
    s, t = (ww * ru - uw * rw) / det, (uu * rw - uw * ru) / det
    weights[0], weights[1], weights[2] = max(1.0 - s - t, 0.0), max(s, 0.0), max(t, 0.0)
    total = weights[0] + weights[1] + weights[2]
    for corner in range(3):
        weights[corner] /= total


@njit(cache=True, inline='always')
def _unit_normal(positions, element, out):
    """``out`` (d,): the unit normal of the edge (2D) or triangle (3D) ``element``."""
    a, b = positions[element[0]], positions[element[1]]
    if out.shape[0] == 2:
        out[0], out[1] = a[1] - b[1], b[0] - a[0]
    else:
        c = positions[element[2]]
        u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        w0, w1, w2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        out[0], out[1], out[2] = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
    out /= np.sqrt(np.sum(out * out))


class ContactSlide:
    """How far the fruit slid down the jaws at its contacts (m), fed every step result.

    The slide is the mean vertical velocity of the nodes a jaw holds, relative to the
    jaws, integrated over the steps fed with ``sliding`` (never below 0: a fruit pushed
    back up has not slid). A node stuck to its jaw moves with it, so only sliding
    counts, not the fruit's elastic sag or its relaxation once lifted off the table,
    which move its centroid: ``centroid_drop``, the largest
    ``StepResult.slip_distance`` of those steps, is that separate measure.

    The compiled multi-step advance (``core.advance_kernels``, ``StopRules.slide``)
    integrates the same sum over the steps it runs unseen: ``state`` is what it starts
    from, ``include`` takes what it leaves. Works for 2D and 3D results: the last
    coordinate column is the height.

    Args:
        time: s, the time of the last step before the first one fed.
    """

    def __init__(self, time: float):
        #: m, the slide now
        self.slide = 0.0
        #: m, the largest slide so far (what a grasp's slip is)
        self.largest = 0.0
        #: m, the largest drop of the centroid relative to the jaws so far
        self.centroid_drop = 0.0
        #: s, the time of the step before the next one fed (its time step)
        self.previous_time = float(time)
        self._jaw_faces = None

    def state(self) -> tuple[float, float, float]:
        """(slide, largest slide, centroid drop), m: ``StopRules.slide_from``."""
        return self.slide, self.largest, self.centroid_drop

    def update(self, result, sliding: bool = True) -> None:
        """Take a step's result; integrate it when ``sliding`` (the machine's phase is
        one in which the slide counts), else only note its time."""
        if sliding:
            self._integrate(result)
            self.centroid_drop = max(self.centroid_drop, float(result.slip_distance))
        self.previous_time = float(result.time)

    def include(self, skipped, sliding: bool = True) -> None:
        """Take what the steps a ``Simulation.advance`` ran unseen leave
        (``core.multistep.Skipped``), the last step excluded: their slide when they
        integrated it (``sliding``, as ``StopRules.slide`` was), the time before it."""
        if sliding:
            self.slide, self.largest, self.centroid_drop = skipped.slide
        self.previous_time = float(skipped.previous_time)

    def _integrate(self, result) -> None:
        if self._jaw_faces is None:
            # whether obstacle k is a jaw's face, at k + 1 (-1: no obstacle): a table
            # look-up instead of np.isin, which costs tens of us a step
            jaws = [name.split('.')[0] in ('left_jaw', 'right_jaw')
                    for name in result.obstacle_names]
            self._jaw_faces = np.array([False, *jaws])
        dt = result.time - self.previous_time
        nodes = self._jaw_faces[result.contact_obstacle + 1]
        if dt > 0 and np.count_nonzero(nodes):
            rising = result.velocities[:, -1][nodes]
            # their mean (``np.mean``'s sum and division, without its overhead)
            relative = float(rising.sum() / rising.size) - result.lift_velocity
            self.slide = max(0.0, self.slide - relative * dt)
            self.largest = max(self.largest, self.slide)
