"""The compiled barrier solve (``core.barrier_newton``) run from Python: which solvers it
covers (``supports``), the problem and its barriers' parts made once per solver
(``CompiledSolve``; it holds the solver's ``linear_solve.LinearSolveState``, so the kept
preconditioner and the work counters are the solver's own), and a solve's arguments
(``CompiledSolve.arguments``) for ``barrier_newton.solve_from``, the compiled
``newton.newton_iteration`` on it with the warm start and the solve that goes on past
its limit (``fast_solver.PatternCachingSolver.solve``'s, and a soft-body step's,
``core.soft_step_kernels``). Each
barrier's ``barrier_part.BarrierPart`` is the barrier's own (its step state, kept
candidates and last evaluation), so nothing is handed in or back.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core import barrier_newton as bn


#: no warm start
_NONE = np.zeros(0)


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
        #: the Newton steps (m/s) of a call and of a solve (``arguments``)
        self.steps = (np.zeros(0), np.zeros(0))
        #: what the Newton matrix kept at a solve's end was made for (``solve_from``'s
        #: ``kept``, ``kept_filters``)
        self.kept = np.zeros(bn.K_SIZE)
        self.kept_filters = np.zeros((n // 2, 2, 2))
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

    def arguments(self, q_n, v_n, dt, con, stiffness, max_iterations, counts, warm,
                  progress, carry) -> tuple:
        """``barrier_newton.solve_from``'s arguments up to its ``progress`` (the start, the
        alternative and the solution's array follow) for a solve from positions ``q_n``,
        velocities ``v_n`` (n_dof,) over dt s: ``con`` as ``fast_solver.as_cone`` makes it,
        no sliding nodes; ``stiffness`` K_n's CSC values (or empty); ``counts`` the
        solver's work counters (added to); ``warm`` the last solve's (q_n, dt, q) if made
        with this dt, else None; ``progress`` (span, factor, limit) of a solve that goes
        on past ``max_iterations``; ``carry``: a solve may start with the Newton matrix
        the last one kept (``barrier_newton.solve_from``). After the call, ``finished``."""
        settings, tol = self.settings, self.tolerance
        filters = con.filters
        if not filters.flags.writeable:  # a read-only array is typed apart: a copy, kept
            if self.filters[0] is not filters:
                self.filters = (filters, filters.copy())
            filters = self.filters[1]
        history, done = self.steps
        if history.size != max_iterations or done.size < (progress[2] + 1) * max_iterations:
            self.steps = history, done = (np.zeros(max_iterations),
                                          np.zeros((progress[2] + 1) * max_iterations))
        warm_q_n, warm_q = (warm[0], warm[2]) if warm is not None else (_NONE, _NONE)
        return (self.problem, q_n, v_n, dt, dt ** 2, stiffness, filters,
                (settings.cg_tolerance, settings.cg_error_fraction * tol * dt,
                 settings.cg_relative_floor * tol * dt),
                tol, max_iterations, warm is not None, warm_q_n, warm_q, history, counts, done,
                (float(progress[0]), float(progress[1]), float(progress[2])),
                self._kept(carry), self.kept_filters)

    def _kept(self, carry: bool) -> np.ndarray:
        """``solve_from``'s ``kept`` (``barrier_newton.K_SIZE``,), carrying set."""
        self.kept[bn.K_CARRY] = 1.0 if carry else 0.0
        return self.kept

    def forget(self) -> None:
        """Keep no Newton matrix for the next solve (the solver's ``reset``)."""
        self.flags[bn.F_KEPT] = -1

    def finished(self) -> np.ndarray:
        """After a ``barrier_newton.solve_from`` call: AssertionError where a barrier's
        Hessian fell outside its pattern (as the interpreted route raises it); the
        reaction (n_dof,) N of its solution (valid until the next solve)."""
        for barrier in self.barriers:
            barrier.check_compiled()
        return self.work[4]
