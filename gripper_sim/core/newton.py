"""The Newton iteration of an implicit Euler step: one implementation for every set-up.

``newton_iteration`` minimises the step's incremental potential Phi (stepper.py) over
the free directions of the contact filter S. Its source is one function; what it
iterates on is a *problem* reached only through the hook functions below:

- compiled (``newton_iteration``, numba): the problem is a tuple of arrays, and each
  hook has a compiled implementation for it registered with ``numba.extending.overload``
  by the module that builds the tuple (``core.kernels``: the 2D shell's block band with
  the pressure's rank one, the 2D solid's sparse block LDL^T);
- interpreted (``newton_iteration_interpreted``: ``newton_iteration.py_func``, the same
  source run by Python): the problem is an object whose methods of the hooks' names do
  the work - ``fast_solver._NewtonProblem`` (the 3D fruits, the barrier model, soft
  fingers: energies in Python calling compiled kernels into a fixed CSC pattern, Newton
  systems by conjugate gradients with a kept block LDL^T), and in the tests the
  reference's (``test/reference_solver.py``: triplets summed into a sparse matrix,
  SuperLU). The loop's vector work is in small compiled helpers, so interpreting it costs
  microseconds an iteration.

The iteration (a chord or modified Newton method, Ortega & Rheinboldt 1970, sec. 7.1):
- start: the caller's, or of two (``lower_start``, the barrier model's 2D steps) the one
  of lower Phi;
- convergence: max |dq| / dt < tol (m/s); a step that small is taken whole;
- a *fresh* iteration assembles the Newton matrix S H S + (I - S) at the iterate and
  adds ``shift`` times the filtered inertia S M / dt^2 for the first shift of ``SHIFTS``
  whose direction descends (an indefinite Hessian: buckling skin, compressed flesh) and,
  for a shift above 0, whose matrix is not known to be indefinite (the problem's
  ``definite``; Nocedal & Wright, Numerical Optimization, 2nd ed., sec. 3.4: a Hessian
  modified until positive definite). An indefinite shifted matrix can still give a
  descending direction, and near the shift where one of its eigenvalues crosses zero an
  enormous one (metres for a millimetre's step) whose step bound and line search then
  crawl; the largest shift is taken if it descends, definite or not;
- the matrix is then *kept* (``keep``), from iteration to iteration and from solve to
  solve, while it fits the step (the problem's ``kept_fits``: the same constraints and
  dt, at most ``MAX_FACTOR_AGE`` solves old) and each whole step with it cuts the
  filtered residual max |S g| below ``CONTRACTION`` of the last; a step with the kept
  matrix is tried whole only, and if it fails (no descent, no decrease) that iteration
  is done again fresh;
- the matrix is kept only after steps below the problem's ``keep_limit`` (m/s; the 2D
  kernels: no limit); a first line-search trial above it evaluates the Hessian with
  the gradient (the full step is usually taken, and a new matrix follows);
- line search: backtracking from the problem's ``step_bound`` (1, or less where a
  contact barrier bounds the step or a sliding node's slip turns round) by halves, up
  to ``HALVINGS`` trials, accepting sufficient decrease (Armijo, ``ARMIJO`` of the
  slope) or, with Phi risen by at most ``PHI_ROUNDOFF`` of itself, a filtered gradient
  below half the last.

Hooks (problem first; arrays (n_dof,) float64):
    ``vectors`` -> (grad, grad_trial, g_f, dq, trial): the loop's work vectors.
    ``kept_fits`` -> bool, and counts the solve in the kept matrix's age if it fits.
    ``evaluate(x, hessian, grad)`` -> Phi at x (inf: infeasible), gradient into grad;
        with ``hessian`` the Hessian is kept for ``factorise``.
    ``project(grad, g_f)``: g_f = S grad.
    ``forget``: drop the kept matrix.  ``keep``: keep the matrix just factorised.
    ``factorise(x, shift)`` -> bool (False: singular).
    ``definite`` -> bool: False if the matrix of the last fresh ``direction`` is known
        to be indefinite (True if it is positive definite or its inertia is unknown).
    ``direction(g_f, dq, fresh)`` -> (finite, slope g_f . dq): dq = -A^-1 g_f with the
        matrix just factorised (``fresh``) or the kept one.
    ``step_bound(x, dq)`` -> the line search's first step (<= 1).
    ``keep_limit`` -> m/s, the step size below which the matrix is kept.
    ``filtered_max(g)`` -> max |S g|.
    ``finish(x, grad)``: the converged iterate's reaction (the problem's output).
"""
from __future__ import annotations

import math

from numba import njit

from gripper_sim.core.solver_kernels import max_abs

#: status codes of ``newton_iteration`` (and of the 2D ``kernels.substep``)
OK = 0
INFEASIBLE_START = 1
NO_DESCENT = 2
LINE_SEARCH_FAILED = 3
NO_CONVERGENCE = 4
UNSUPPORTED = 5  # a non-symmetric contact filter (oblique faces): use the reference path
#: the contact passes' last pass still changed the contact set (``contact_passes``): its
#: forces would belong to another set than the one the step keeps
CONTACTS_UNSETTLED = 6

#: work counters (int64 array) ``newton_iteration`` adds to: Newton solves (contact
#: passes), energy evaluations with and without the Hessian, Newton matrix
#: factorisations, substeps (the 2D kernel's), solves with a factor (Newton directions)
C_SOLVES, C_HESSIAN_EVALS, C_EVALS, C_FACTORS, C_SUBSTEPS, C_DIRECTIONS, C_SIZE = range(7)

#: multiples of the (filtered) inertia M / dt^2 added to an indefinite Newton matrix
SHIFTS = (0.0, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5, 1e6)

#: a Newton step with the kept matrix must cut the filtered residual max |S g| below
#: this fraction of the last one, else the matrix is assembled and factorised afresh
CONTRACTION = 0.25

#: Newton solves a kept matrix serves at most before it is made afresh
MAX_FACTOR_AGE = 20

#: sufficient decrease of the line search: Phi(q + s dq) <= Phi(q) + ARMIJO s slope
ARMIJO = 1e-4

#: relative rise of the incremental potential that the line search's gradient test lets
#: pass (above its rounding noise, ~1e-11 at the end of a step's Newton iterations): a
#: step that lowers the projected gradient but raises the potential by more is no progress
#: (a Newton step across the kink of the smoothed friction law, back and forth: 7e-8)
PHI_ROUNDOFF = 1e-9

#: trial steps of a fresh iteration's line search (halving from the first)
HALVINGS = 30


# ---------------------------------------------------------------------- hooks
# The interpreted versions: methods of the problem object. The compiled ones are
# overloads registered for the problem's tuple type (core.kernels).
def vectors(problem):
    return problem.vectors()


def kept_fits(problem):
    return problem.kept_fits()


def evaluate(problem, x, hessian, grad):
    return problem.evaluate(x, hessian, grad)


def project(problem, grad, g_f):
    problem.project(grad, g_f)


def forget(problem):
    problem.forget()


def keep(problem):
    problem.keep()


def factorise(problem, x, shift):
    return problem.factorise(x, shift)


def direction(problem, g_f, dq, fresh):
    return problem.direction(g_f, dq, fresh)


def definite(problem):
    return problem.definite()


def step_bound(problem, x, dq):
    return problem.step_bound(x, dq)


def keep_limit(problem):
    return problem.keep_limit()


def filtered_max(problem, g):
    return problem.filtered_max(g)


def finish(problem, x, grad):
    problem.finish(x, grad)


# ---------------------------------------------------------------------- vector helpers
@njit(cache=True, error_model='numpy', inline='always')
def _trial_point(trial, q, step, dq):
    """trial = q + step dq."""
    for m in range(q.shape[0]):
        trial[m] = q[m] + step * dq[m]


@njit(cache=True, error_model='numpy', inline='always')
def _copy(target, source):
    for m in range(source.shape[0]):
        target[m] = source[m]


# ---------------------------------------------------------------------- the iteration
@njit(cache=True, error_model='numpy', inline='always')
def newton_iteration(problem, q, dt, tol, max_it, history, counts):
    """One implicit Euler step by Newton (see the module's docstring).

    Args:
        problem: what is iterated on (a tuple for the compiled hooks, an object for
            the interpreted ones).
        q: (n_dof,) m, the start (constrained dofs at their targets), overwritten with
            the solution.
        dt: s.  tol: m/s.  max_it: iterations.
        history: (max_it,) output, max |dq| / dt of each iteration's step (m/s).
        counts: (C_SIZE,) int64, work counters added to (see C_*).

    Returns:
        (status, iterations, len(history)); status OK or a failure code.
    """
    grad, grad_t, g_f, dq, trial = vectors(problem)
    n_hist = 0
    counts[C_SOLVES] += 1
    fresh = not kept_fits(problem)  # the next iteration needs a new matrix
    counts[C_HESSIAN_EVALS if fresh else C_EVALS] += 1
    phi = evaluate(problem, q, fresh, grad)
    if not math.isfinite(phi):
        return INFEASIBLE_START, 0, n_hist
    iteration = 0
    while iteration < max_it:
        iteration += 1
        project(problem, grad, g_f)
        found = False
        slope = 0.0
        if fresh:
            forget(problem)
            for shift in SHIFTS:
                counts[C_FACTORS] += 1
                if not factorise(problem, q, shift):
                    continue
                counts[C_DIRECTIONS] += 1
                finite, slope = direction(problem, g_f, dq, True)
                if finite and slope <= 0 and (
                        shift == 0.0 or shift == SHIFTS[-1] or definite(problem)):
                    found = True
                    break
            if not found:
                return NO_DESCENT, iteration, n_hist
            keep(problem)
        else:
            counts[C_DIRECTIONS] += 1
            finite, slope = direction(problem, g_f, dq, False)
            found = finite and slope <= 0
        residual = max_abs(g_f)
        dq_max = max_abs(dq)
        # a step below the tolerance is taken without a line search (the first trial
        # below, accepted as it is): q + dq, or as far as the step bound lets it go (a
        # barrier's gap can be smaller than the tolerance: a whole step crossed it)
        small = dq_max / dt < tol
        accepted = False
        phi_trial = 0.0
        norm = 0.0
        step = 1.0
        # a step with the kept matrix is tried whole only
        tries = HALVINGS if fresh else (1 if found else 0)
        if tries > 0:
            step = step_bound(problem, q, dq)
        limit = keep_limit(problem)
        hessian_at_trial = False
        for trial_index in range(tries):
            _trial_point(trial, q, step, dq)
            norm = step * dq_max / dt
            # a first trial this large, if taken, is followed by a new matrix: its
            # Hessian is evaluated with it
            hessian_at_trial = trial_index == 0 and norm >= limit
            counts[C_HESSIAN_EVALS if hessian_at_trial else C_EVALS] += 1
            phi_trial = evaluate(problem, trial, hessian_at_trial, grad_t)
            if small or math.isfinite(phi_trial) and (
                    phi_trial <= phi + ARMIJO * step * slope
                    or (phi_trial <= phi + PHI_ROUNDOFF * abs(phi)
                        and filtered_max(problem, grad_t) < 0.5 * residual)):
                accepted = True
                break
            step *= 0.5
        if not accepted:
            if fresh:
                return LINE_SEARCH_FAILED, iteration, n_hist
            # the kept matrix failed here: this iteration again with the Hessian at q
            iteration -= 1
        else:
            _copy(q, trial)
            phi = phi_trial
            _copy(grad, grad_t)
            history[n_hist] = norm
            n_hist += 1
            if norm < tol:
                finish(problem, q, grad)
                return OK, iteration, n_hist
            if norm < limit and (
                    fresh or filtered_max(problem, grad) < CONTRACTION * residual):
                fresh = False
                continue
        fresh = True
        if not (accepted and hessian_at_trial):
            counts[C_HESSIAN_EVALS] += 1
            phi = evaluate(problem, q, True, grad)
    return NO_CONVERGENCE, max_it, n_hist


@njit(cache=True, error_model='numpy')
def lower_start(problem, q, alternative, counts):
    """Sets the start q (n_dof,) m to ``alternative`` (n_dof,) m where the incremental
    potential is lower there (``evaluate`` without the Hessian; ``counts`` as
    ``newton_iteration``'s): of two starts of a step the lower is, as a rule, the nearer
    its solution."""
    scratch = vectors(problem)[1]
    counts[C_EVALS] += 2
    if evaluate(problem, alternative, False, scratch) < evaluate(problem, q, False, scratch):
        _copy(q, alternative)


def newton_iteration_interpreted(problem, q, dt, tol, max_it, history, counts):
    """``newton_iteration`` run by Python on a problem object (see the module)."""
    return newton_iteration.py_func(problem, q, dt, tol, max_it, history, counts)
