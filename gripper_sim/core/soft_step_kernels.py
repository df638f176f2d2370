"""The 2D soft-body step's (``barrier.soft_body_step``) set-up and outputs, and the
fruit's measures after it, each one compiled call.

``begin`` sets up the step of the fruit's barrier (``barrier_part.begin_with_starts``:
the starts pushed ahead of the faces, the predictor's checked) and of the soft bodies'
self-contact where it keeps its quiet region (its collision mesh's start and step state,
``barrier_part.set_step``), and says whether the way to the predictor's start is clear
of both; ``outputs`` gives the solved step's velocities, the reaction on the prescribed
dofs, each outline node's partner and the contact forces. They do what
``BarrierContact.set_up_starts``, ``begin_step``, ``reachable``'s compiled checks and
``soft_body_step``'s outputs do one by one, in their order and arithmetic, so a step's
every number is theirs (``test/test_soft_step_kernels.py``); what needs Python (a quiet
region sought again, a start that is not the predictor's, the exact CCD, forces the
last evaluation did not leave) the caller does. The Newton solve between them is
``barrier_newton.solve_from`` (``fast_solver.PatternCachingSolver.solve``). After the
step, ``held_measures`` gives the fruit's measures its barrier's forces make (normal
forces, the nodes each jaw holds, the held length, the outline's measures) for
``Simulation._measure``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from gripper_sim.core.barrier_kernels import (held_normal_forces, largest_relative_move,
                                              mesh_vertices)
from gripper_sim.core.barrier_part import (begin_with_starts, kept_forces, partners, quiet,
                                           set_step, start_clear)
from gripper_sim.core.contact import jaw_sides
from gripper_sim.core.measures import held_length_of, outline_measures

#: ``begin``'s statuses: the self-contact's quiet region must be sought again (nothing
#: set up); the step is set up
SEEK_QUIET, SET_UP = range(2)


@njit(cache=True)
def quiet_kept(part, q, keep):
    """Whether the self-contact ``part``'s quiet region serves a step from positions q
    (2 n,) m (``BarrierContact._quiet_region`` keeps it: every vertex within ``keep``
    times its reach of where it was sought, each body's mean move taken off)."""
    return part.has_quiet and largest_relative_move(
        q, part.dof_pairs, part.quiet_anchor, part.vertex_body,
        part.n_bodies) <= keep * part.quiet_reach


@njit(cache=True)
def begin(part, x_n, v_start, dt, old_corners, new_corners, rubbing, mu_s, mu_k, surface,
          origins, normals, tangents, half_extents, thickness, shifts, fraction, fixed,
          targets, self_part, has_self, keep, self_rubbing, self_mu_s, self_mu_k):
    """The step's set-up from positions ``x_n`` (n, 2) m, the predictor's velocities
    ``v_start`` (n, 2) m/s: the fruit's barrier ``part`` as
    ``barrier_part.begin_with_starts`` (its arguments of the same names; the fixed
    nodes at their targets in both starts, the way to x_n's checked only where the
    predictor's is not clear) and, with ``has_self``, the self-contact ``self_part``
    (no faces; its coefficients ``self_mu_s``, ``self_mu_k`` (n_v,), ``self_rubbing``)
    with its quiet region kept, if ``quiet_kept`` with ``keep``.

    Returns:
        (status: SEEK_QUIET (nothing set up) or SET_UP, whether the fruit's barrier
        has lagged friction, its collision mesh's start (n_m, 2) m, its faces' largest
        shift m, x_n's start, the predictor's (n, 2) m, whether its compiled check clears
        the way to the predictor's, to x_n's, the self-contact's collision mesh's start
        (n_v, 2) m and whether it has lagged friction, whether the predictor's start is
        clear of the self-contact too (the caller may take it without more checks)).
    """
    q_n = x_n.ravel()
    no_corners = np.zeros((0, 2))
    if has_self and not quiet_kept(self_part, q_n, keep):
        return (SEEK_QUIET, False, no_corners, 0.0, x_n, x_n, False, False, no_corners,
                False, False)
    (has_friction, start, faces_shift, plain, predicted, predicted_clear, plain_clear,
     _) = begin_with_starts(part, x_n, v_start, dt, old_corners, new_corners, rubbing,
                            mu_s, mu_k, surface, origins, normals, tangents, half_extents,
                            thickness, shifts, fraction, fixed, targets, False)
    self_start = no_corners
    self_friction = False
    clear = predicted_clear
    if has_self:
        self_start = np.empty((self_part.dof_pairs.shape[0], 2))
        mesh_vertices(q_n, self_part.dof_pairs, no_corners, self_start)
        self_friction = set_step(self_part, no_corners, self_start, self_rubbing, True,
                                 self_mu_s, self_mu_k, self_part.quiet_anchor,
                                 self_part.quiet_reach, True)
        if clear:
            q = predicted.ravel()
            clear = quiet(self_part, q, np.zeros(0)) or start_clear(self_part, q_n, q, 0.0)
    return (SET_UP, has_friction, start, faces_shift, plain, predicted,
            predicted_clear, plain_clear, self_start, self_friction, clear)


@njit(cache=True)
def outputs(part, q, x_n, dt, solved_reaction, fixed_dofs, vertex_nodes, owner, v,
            reaction, partner, forces):
    """A step's outputs at its solution q (2 n,) m from positions ``x_n`` (n, 2) m over
    dt s: the velocities ``v`` (2 n,) m/s, ``reaction`` (2 n,) N the solve's reaction
    ``solved_reaction`` on ``fixed_dofs`` (0 elsewhere), ``partner`` (n,) each outline
    node's (``barrier_part.partners``; ``owner`` the body of each collision-mesh vertex,
    the outlines' at ``vertex_nodes``) and, where the fruit's barrier ``part``'s last
    evaluation was at q, ``forces`` (2 n,) N its forces with friction
    (``barrier_part.kept_forces``). Returns whether ``forces`` is written (else the
    caller evaluates them)."""
    q_n = x_n.ravel()
    for k in range(q.shape[0]):
        v[k] = (q[k] - q_n[k]) / dt
    reaction[:] = 0.0
    for k in range(fixed_dofs.shape[0]):
        reaction[fixed_dofs[k]] = solved_reaction[fixed_dofs[k]]
    partners(part, q, vertex_nodes, owner, partner)
    return kept_forces(part, q, True, forces)


@njit(cache=True)
def held_measures(part, q, x, obstacle, side_of_obstacle, surface, skin, rest_segments,
                  depth, normal, on_left, on_right, held, lengths, pressure):
    """The fruit's measures that its barrier's forces give after a soft-body step, where
    its last evaluation was at the positions q (2 n,) m of the fruit and the soft bodies
    (``barrier_part.kept_forces``): each of the fruit's nodes' normal force ``normal``
    (n_f,) N (``held_normal_forces``, ``obstacle`` (n_f,) the body holding each node),
    the nodes each jaw holds ``on_left``, ``on_right`` and either ``held`` (n_f,) bool
    (``contact.jaw_sides``, ``side_of_obstacle`` as it takes it), and at the fruit's
    positions ``x`` (n_f, 2) m the held outline's length (``measures.held_length_of``,
    ``lengths`` (n_s,) scratch) and the outline's measures (``measures.outline_measures``
    of ``surface``, ``skin``, ``rest_segments``, ``depth`` m; each outline node's
    pressure into ``pressure`` (n_s,) Pa): what ``SimulationFacade._step_measures`` and
    ``Simulation._measure`` read one by one, in their order and arithmetic.

    Returns:
        (whether the forces were kept (else nothing is written), whether the left and
        the right jaw hold any node, the held length m, the width m, the largest skin
        strain, the peak line pressure Pa).
    """
    forces = np.empty(q.shape[0])
    if not kept_forces(part, q, False, forces):
        return False, False, False, 0.0, 0.0, 0.0, 0.0
    held_normal_forces(forces.reshape((-1, 2)), obstacle, normal)
    any_left, any_right = jaw_sides(obstacle, side_of_obstacle, on_left, on_right)
    for i in range(held.shape[0]):
        held[i] = on_left[i] | on_right[i]
    length = held_length_of(x, skin, surface, held, lengths)
    width, max_strain, peak = outline_measures(x, surface, skin, rest_segments, normal,
                                               depth, pressure)
    return True, any_left, any_right, length, width, max_strain, peak
