"""An energy that holds a 3D fruit's rolling while it settles on the table
(``SimulationFacade._settle``): a round fruit's rest on a flat table is neutral in
rolling, and a faceted skin rolls slowly onto a facet as it settles (the default shell
0.11 mm aside, the solid apple 3 mm, the 362-node apple with ``contact.model: ipc`` 0.54
mm and still creeping after 60 settling steps, so that its settle never ends). Held, the
settle ends where the fruit was placed; the roll onto the facet happens in the run's
first second, as it did before the fruit started settled.

E = 1/2 sum_a K_a g_a(q)^2 with g_a = w_a . (q - q_ref), the amplitude of rigid mode a
of the fruit's move from the step's start q_ref (its nodes' rows; w_a is 0 elsewhere):
the shifts along x and y and the small rotations about the horizontal axes through its
centroid (u_a (n_dof,), w_a = M u_a / (u_a^T M u_a), M the lumped masses). K_a = HOLD x
(u_a^T M u_a) / dt^2 makes each mode HOLD times as stiff as its inertia over the step.
The Hessian is the four rank-one terms K_a w_a w_a^T, so the step's solve itself keeps
the fruit from rolling, its contact with the table included (taking the rolling off each
step's result instead pushed nodes of the contact patch into the table). Inactive (no
value, no terms) outside the settle.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import KernelEnergy

#: each held mode's stiffness over its inertia in the step, M_a / dt^2
HOLD = 1e8


class RollingHold(KernelEnergy):
    """Args:
        masses: (n,) kg, the fruit's lumped masses (its nodes first in q).
        n_dof: the solver's unknowns (3 n and any deformable finger's after them).
    """

    elastic = False
    #: no sparse Hessian: rank-one terms only
    dofs = None

    def __init__(self, masses: np.ndarray, n_dof: int):
        self.masses = np.asarray(masses, dtype=float)
        self.n_dof = int(n_dof)
        self._held: tuple | None = None

    def hold(self, start: np.ndarray | None, dt: float = 0.0) -> None:
        """Hold the rolling of the fruit's move from its positions ``start`` (n, 3) m
        over a step of ``dt`` s; None: inactive."""
        if start is None:
            self._held = None
            return
        m, n = self.masses, self.masses.size
        x = np.array(start, dtype=float).reshape(n, 3)
        r = x - (m @ x) / m.sum()
        modes = np.zeros((4, n, 3))
        modes[0, :, 0] = 1.0
        modes[1, :, 1] = 1.0
        modes[2, :, 1], modes[2, :, 2] = -r[:, 2], r[:, 1]   # about x
        modes[3, :, 0], modes[3, :, 2] = r[:, 2], -r[:, 0]   # about y
        modal_masses = np.einsum('anc,n,anc->a', modes, m, modes)
        weights = np.zeros((4, self.n_dof))
        weights[:, :3 * n] = (modes * m[None, :, None]).reshape(4, -1) / modal_masses[:, None]
        self._held = (x.ravel(), weights, HOLD * modal_masses / dt ** 2)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter, hessian: bool = True):
        """Adds the gradient (N) into ``grad``; returns (value J, the rank-one terms
        [(K_a N/m, w_a)] with ``hessian``)."""
        if self._held is None:
            return 0.0, []
        x_ref, weights, stiffness = self._held
        amplitudes = weights[:, :x_ref.size] @ (q[:x_ref.size] - x_ref)
        grad += (stiffness * amplitudes) @ weights
        terms = [(float(k), w) for k, w in zip(stiffness, weights)] if hessian else []
        return 0.5 * float(stiffness @ amplitudes ** 2), terms
