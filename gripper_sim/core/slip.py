"""When a grasp slipped, and when the fruit is slipping: the one definition of each.

``grasp_slipped`` (the outcome) is shared by the grasp state machine (the node's Grasp
action result, ``pick``) and the analysis of a recording (``analyze``);
``jaw_contacts_sliding`` (``StepResult.slipping``, ``FruitState.slipping``) by both
simulation facades and the 2D fast path.
"""
from __future__ import annotations

import numpy as np

#: slip (m) of the fruit relative to the jaws beyond which the grasp slipped
SLIP_TOLERANCE = 1e-3

#: m/s, speed along a jaw face, relative to it, above which a contact node slides (a
#: stuck node moves with its jaw; a soft pad's friction creeps below 1e-4 m/s)
SLIDING_SPEED = 1e-3


def grasp_slipped(held_slip: float, dropped: bool = False) -> bool:
    """Whether a grasp slipped.

    Args:
        held_slip: m, the fruit's slip relative to the jaws (``StepResult.slip_distance``,
            ``FruitState.slip_distance``) at the end of the hold: measured from the
            lift-off, or from the grip when there is no lift. Pushes of one jaw before
            the grip and the fruit's motion during a release do not count.
        dropped: no jaw touched the fruit at some time between the lift-off (or the
            grip) and the end of the hold.
    """
    return bool(dropped) or held_slip > SLIP_TOLERANCE


def jaw_contacts_sliding(velocities: np.ndarray, holder: np.ndarray, jaw_of_face: np.ndarray,
                         face_normals: np.ndarray, face_velocities: np.ndarray) -> bool:
    """Whether the fruit is slipping in the jaws: on either jaw, more than half of the nodes
    it holds move along its faces faster than ``SLIDING_SPEED`` relative to them.

    Only the motion at the contacts counts: a fruit that deforms while every contact node
    sticks (it sags under its weight, bulges in a squeeze) is not slipping.

    Args:
        velocities: (n_nodes, d) m/s, node velocities.
        holder: (n_nodes,) int, the obstacle (face) holding each node, -1 if none.
        jaw_of_face: (n_faces,) int, the jaw (0 left, 1 right) of each face, -1 for the
            faces of no jaw (table, walls).
        face_normals: (n_faces, d) unit normals.  face_velocities: (n_faces, d) m/s.
    """
    held = np.flatnonzero(holder >= 0)
    face = holder[held]
    jaw = jaw_of_face[face]
    on_jaw = jaw >= 0
    if not np.any(on_jaw):
        return False
    held, face, jaw = held[on_jaw], face[on_jaw], jaw[on_jaw]
    relative = velocities[held] - face_velocities[face]  # (k, d)
    normals = face_normals[face]
    along = relative - np.sum(relative * normals, axis=1)[:, None] * normals
    sliding = np.sum(along * along, axis=1) > SLIDING_SPEED ** 2
    for side in (0, 1):
        mine = jaw == side
        if 2 * np.count_nonzero(sliding & mine) > np.count_nonzero(mine):
            return True
    return False
