"""The compiled barrier solve (``core.barrier_newton``) run from Python: which solvers it
covers (``supports``), the problem and its barriers' parts made once per solver
(``CompiledSolve``; it holds the solver's ``linear_solve.LinearSolveState``, so the kept
preconditioner and the work counters are the solver's own), and one solve
(``CompiledSolve.run``): the compiled ``newton.newton_iteration`` called on it. Each
barrier's ``barrier_part.BarrierPart`` is the barrier's own (its step state, kept
candidates and last evaluation), so nothing is handed in or back.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core import barrier_newton as bn
from gripper_sim.core import newton


@dataclass(frozen=True)
class SolveSettings:
    """The solver's constants (``fast_solver``'s of the same names in capitals)."""

    keep_below: float
    cg_tolerance: float
    cg_error_fraction: float
    cg_relative_floor: float


def supports(dim: int, energies_after_table: list, step_bounding: list) -> bool:
    """Whether ``CompiledSolve`` covers a solver of dimension ``dim`` whose energies after
    its table are ``energies_after_table`` and whose step-bounding energies are
    ``step_bounding`` (see ``core.barrier_newton``)."""
    from gripper_sim.core.barrier import BarrierContact
    barriers = list(energies_after_table)
    return (dim == 2 and 0 < len(barriers) <= 2
            and all(type(b) is BarrierContact and b.dimension == 2 for b in barriers)
            and list(step_bounding) == barriers)


class CompiledSolve:
    """The compiled problem of one solver (``BarrierProblem``), its barriers' parts
    (``BarrierPart``) and the arrays they share with Python.

    Args:
        settings: the solver's constants.
        masses: (n,) kg per dof.  alpha: 1/s.  beta: s.  tolerance: m/s.
        table: the solver's ``EnergyTable`` (``kernel_arrays``).
        pattern: the solver's CSC arrays as ``barrier_newton``'s ``pattern`` field.
        linear: the solver's ``linear_solve.LinearSolveState``.
        barriers: [(BarrierContact, its scatter)] the energies after the table.
    """

    def __init__(self, settings: SolveSettings, masses, alpha, beta, tolerance, table,
                 pattern: tuple, linear, barriers: list):
        from gripper_sim.core.stepper import FRICTION_SMOOTHING

        self.settings, self.tolerance, self.beta = settings, tolerance, beta
        #: what the problem was made for: each barrier, its scatter, its part
        self.key = self.key_of(barriers)
        self.barriers = [barrier for barrier, _ in barriers]
        n = masses.size
        p = table.pressures
        #: the last read-only filters with their copy
        self.filters = (None, None)
        self.parts = tuple(barrier.compiled_part(scatter) for barrier, scatter in barriers)
        #: the loop's vectors (5, n), the friction gradient, CG's solution, S g, the
        #: reaction
        self.work = (np.empty((5, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n))
        self.flags = np.zeros(bn.F_SIZE, np.int64)
        self.problem = bn.new_problem((
            masses, alpha, beta, FRICTION_SMOOTHING, settings.keep_below * tolerance,
            (np.zeros(0, np.int64), np.zeros((0, 1, 2)), np.zeros(0), np.zeros((0, 1))),
            (*table.kernel_arrays(), np.zeros(p)), pattern, linear, self.parts, self.work,
            (np.empty((2, pattern[2].size)), np.empty((2, p, n)), np.empty((2, p)),
             np.zeros(2, np.int64), np.zeros(2)),
            self.flags,
            np.zeros(n), np.zeros(n), 1.0, 1.0, np.zeros(0), np.zeros((n // 2, 2, 2)),
            (0.0, 0.0, 0.0)))

    @staticmethod
    def key_of(barriers: list) -> tuple:
        """What a ``CompiledSolve`` of ``barriers`` [(barrier, scatter)] is made for."""
        return tuple(x for barrier, scatter in barriers
                     for x in (barrier, scatter, barrier.compiled_part(scatter)))

    def fits(self, barriers: list) -> bool:
        """Whether this was made for ``barriers`` [(barrier, scatter)] as they are
        (``key_of``, compared item by item: a solve asks before every run)."""
        key = self.key
        if 3 * len(barriers) != len(key):
            return False
        for k, (barrier, scatter) in enumerate(barriers):
            if (key[3 * k] is not barrier or key[3 * k + 1] is not scatter
                    or key[3 * k + 2] is not barrier.compiled_part(scatter)):
                return False
        return True

    def run(self, q_n, v_n, dt, con, stiffness, q, alternative, history, max_iterations,
            counts):
        """One Newton solve: (status, iterations, len(history), reaction (n_dof,) N or
        None); ``q`` (n_dof,) m, the start, overwritten with the solution (``alternative``
        (n_dof,) m, if not empty, the start where the potential is lower); ``con`` as
        ``fast_solver.as_cone`` makes it, no sliding nodes; ``stiffness`` K_n's CSC values
        (or empty); ``counts`` the solver's work counters (added to). Raises
        AssertionError where a barrier's Hessian falls outside its pattern (as the
        interpreted route does)."""
        flags, settings, tol = self.flags, self.settings, self.tolerance
        flags[bn.F_KEPT] = flags[bn.F_LAST] = -1
        filters = con.filters
        if not filters.flags.writeable:  # a read-only array is typed apart: a copy, kept
            if self.filters[0] is not filters:
                self.filters = (filters, filters.copy())
            filters = self.filters[1]
        status, iterations, n_hist = bn.solve(
            self.problem, q_n, v_n, dt, dt ** 2, stiffness, filters, settings.cg_tolerance,
            settings.cg_error_fraction * tol * dt, settings.cg_relative_floor * tol * dt,
            q, alternative, tol, max_iterations, history, counts)
        for barrier in self.barriers:
            barrier.check_compiled()
        reaction = self.work[4].copy() if status == newton.OK else None
        return status, iterations, n_hist, reaction
