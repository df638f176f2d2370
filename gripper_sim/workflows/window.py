"""The grasp window: the grip forces that hold a fruit without bruising it, by simulation.

- Minimum force: the smallest grip force at which the fruit is carried through the
  scenario's close, squeeze, lift, transport and a hold (``squeeze.time``) and slides
  less than ``window.max_slip`` in the jaws on the way (from the lift-off, when the
  table lets go, to the end of the hold): such a trial is 'held'. Found by bisection
  over full simulations, from a bracket seeded with the rigid-flat-jaw estimate
  m g / (2 mu_s) (validation.md section 6) and m g / (2 mu_k), widened until it
  brackets. A trial whose grip stays below its command ('not reached') ends the climb:
  no larger command holds, so the search looks below it (``hold_verdict``, ``bisection``).
- Maximum force: the largest grip force at which the same run leaves the fruit
  undamaged (neither bruised nor crushed), by bisection seeded with the Hertz force at
  which the peak pressure reaches the bruise threshold,
  F = p_b^3 pi^3 R^2 / (6 E*^2) (validation.md section 3).
- The window is [minimum, maximum] when minimum <= maximum, else there is none. Both
  bounds are commanded forces; each is also reported as the peak grip force measured
  in its trial (``min_force_measured``, ``max_force_measured``).

Each trial is a fresh simulation starting with the jaws open at the grasp height (the
scenario's approach skipped), run by ``evaluate_grasp`` (``workflows.grasp.evaluate``, the
evaluation the ``pick`` command and studies share). A trial stops early once its
answer is known (dropped or bruised). A trial whose solver fails (``ConvergenceError``)
counts as neither holding nor safe, so that force stays out of the window; so does a
'bruise' trial whose grip never reached its command (the fingers deliver no more: a
Fin Ray that buckles, jaws at their stop), which is undamaged but not a grasp at that
force. The two bisections (``window_bisections``) are driven here by
``workflows.speculative``: one after the other in this process, or on several worker
processes (``grasp_window``'s ``workers``) side by side and looking ahead, with the
same trials and window; and as one generator, ``window_search``, by
``gripper_sim.workflows.study`` over a Dask cluster.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Generator, Iterable, Mapping

import numpy as np

from gripper_sim.core.damage import contact_modulus
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core3d.fruit import build_fruit3d
from gripper_sim.errors import GripperSimError
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import (FORCE_REACHED, PINCHED, SOLVER_FAILED,
                                         GraspEvaluation, evaluate)
from gripper_sim.workflows.scenario import PickAndPlace, Scenario
from gripper_sim.workflows.speculative import (InlinePool, ProcessPool, Request, Search,
                                               run_searches)

#: relative width of the final bisection brackets
TOLERANCE = 0.03
#: how many times a bracket end may be halved or doubled looking for a bracket
MAX_WIDENINGS = 8
#: a trial's verdict when its grip stayed below its command (``Trial.reached``)
NOT_REACHED = 'not reached'
#: the hold search's third verdict (beside True and False): not held, and the fingers did
#: not reach this grip, so they reach none above it either (``hold_verdict``)
OUT_OF_REACH = 'out of reach'


@dataclass
class Trial:
    """One simulated grasp of the window and the window's verdict on it.

    Attributes:
        force: N, the commanded grip force.
        kind: 'hold' (does it hold?) or 'bruise' (does it bruise?).
        held: it counts as holding: carried, slid less than ``window.max_slip``.
        slipped: carried but slid ``window.max_slip`` or more (or dropped).
        bruised: damaged (bruised or crushed).
        outcome: the run's own one-word outcome (``core.vocabulary.OUTCOMES``).
        slip_distance: m, how far the fruit slid in the jaws.
        peak_grip_force: N, the measured peak grip force.
        peak_jaw_pressure, peak_table_pressure: Pa, contact pressure at the jaws, on
            the table.
        peak_damage_pressure: Pa, the damage model's pressure.
        bruised_at: where it first bruised ('jaws', 'table') or None.
        wall_time: s.
    """

    force: float
    kind: str
    held: bool
    slipped: bool
    bruised: bool
    outcome: str
    slip_distance: float
    peak_grip_force: float
    peak_jaw_pressure: float
    peak_table_pressure: float
    peak_damage_pressure: float
    bruised_at: str | None
    wall_time: float

    @property
    def verdict(self) -> str:
        """One word for the trial line: held, slipped (or the run's word when it did
        not carry the fruit) for a 'hold' trial; bruised or safe (or 'solver failed',
        'pinched', 'not reached') for a 'bruise' one."""
        if self.kind == 'bruise':
            if self.outcome in (SOLVER_FAILED, PINCHED):
                return self.outcome
            if not self.bruised and not self.reached:
                return NOT_REACHED
            return 'bruised' if self.bruised else 'safe'
        if self.held:
            return 'held'
        if not self.reached:
            return NOT_REACHED
        return 'slipped' if self.outcome in ('held', 'slipped', 'placed') else self.outcome

    @property
    def reached(self) -> bool:
        """The grip reached its command: not a run that ended 'failed' with its peak grip
        below ``FORCE_REACHED`` of it (the jaws at their stop, a finger buckled)."""
        return not (self.outcome == 'failed'
                    and self.peak_grip_force < FORCE_REACHED * self.force)

    @property
    def safe(self) -> bool:
        """A 'bruise' trial's verdict for the window: undamaged, and at its commanded
        grip (a grip the fingers cannot deliver is not a safe grasp at that force)."""
        return not self.bruised and self.reached


def hold_verdict(trial: Trial) -> bool | str:
    """A 'hold' trial's verdict for the hold search: True (held), False (not held), or
    ``OUT_OF_REACH`` (not held, its grip not reached: no larger command holds either)."""
    if trial.held:
        return True
    return False if trial.reached else OUT_OF_REACH


@dataclass
class GraspWindow:
    """Result of ``grasp_window``.

    Attributes:
        min_force: N commanded, smallest force that held: slid less than ``max_slip``
            (None: none up to gripper.max_force, or none below the grip the fingers
            reach: ``min_force_limited_by``).
        max_force: N commanded, largest force that did not bruise and whose trial
            reached its grip (``Trial.safe``; None: no force tried was; inf: every one up
            to gripper.max_force was).
        min_force_measured, max_force_measured: N, the peak grip force measured in the
            trial of each bound (None where the bound is None or inf).
        min_estimate, max_estimate: N, the closed-form seeds (m g / 2 mu; Hertz).
        trials: every simulated grasp, in order.
        wall_time: s, time to compute the window.
        max_slip: m, ``window.max_slip``.
        table_bruise_estimate: N, the table load at which the fruit bruises on the table
            (``table_bruise_load``); the trials say where each bruised (``bruised_at``).
        workers: processes the trials ran on.
        look_ahead_trials: trials run ahead on spare workers that the searches did not
            take (not in ``trials``).
    """

    fruit: str
    finger: str
    min_force: float | None
    max_force: float | None
    min_estimate: float
    max_estimate: float
    mass: float
    friction: float
    tolerance: float
    trials: list = field(default_factory=list)
    wall_time: float = 0.0
    max_slip: float = 0.0
    table_bruise_estimate: float = 0.0
    min_force_measured: float | None = None
    max_force_measured: float | None = None
    workers: int = 1
    look_ahead_trials: int = 0

    @property
    def min_force_limited_by(self) -> str | None:
        """Why nothing held (``lower_bound_limited_by``)."""
        return lower_bound_limited_by(self.min_force, self.trials)

    @property
    def max_force_limited_by(self) -> str | None:
        """What ended the safe side at ``max_force`` (``upper_bound_limited_by``)."""
        return upper_bound_limited_by(self.max_force, self.trials)

    @property
    def exists(self) -> bool:
        """There is a force that holds without bruising."""
        return (self.min_force is not None and self.max_force is not None
                and self.min_force <= self.max_force)

    def as_dict(self) -> dict:
        def number(value):
            if value is None:
                return None
            return 'inf' if math.isinf(value) else value
        return dict(fruit=self.fruit, finger=self.finger, min_force=number(self.min_force),
                    max_force=number(self.max_force), window=bool(self.exists),
                    min_estimate=float(self.min_estimate),
                    max_estimate=float(self.max_estimate), mass=float(self.mass),
                    friction=float(self.friction), tolerance=self.tolerance,
                    wall_time=self.wall_time, max_slip=self.max_slip,
                    table_bruise_estimate=self.table_bruise_estimate,
                    min_force_measured=self.min_force_measured,
                    max_force_measured=self.max_force_measured,
                    min_force_limited_by=self.min_force_limited_by,
                    max_force_limited_by=self.max_force_limited_by,
                    workers=self.workers, look_ahead_trials=self.look_ahead_trials,
                    trials=[dict(vars(t), verdict=t.verdict) for t in self.trials])

    def answer_dict(self) -> dict:
        """``as_dict`` without what depends on the run rather than the answer (the wall
        times, the worker count, the look-ahead trials): equal for equal windows."""
        data = self.as_dict()
        for key in ('wall_time', 'workers', 'look_ahead_trials'):
            data.pop(key)
        for trial in data['trials']:
            trial.pop('wall_time')
        return data


def bruise_trial_above(max_force: float | None, trials: Iterable[Trial]) -> Trial | None:
    """The 'bruise' trial nearest above ``max_force`` (N), the one that ended the safe
    side; None without a finite ``max_force`` or a trial above it."""
    if max_force is None or math.isinf(max_force):
        return None
    above = [t for t in trials if t.kind == 'bruise' and t.force > max_force]
    return min(above, key=lambda t: t.force) if above else None


def upper_bound_limited_by(max_force: float | None, trials: Iterable[Trial]) -> str | None:
    """What ended a window's safe side at ``max_force`` (N): 'bruise'; 'solver
    failure' when the nearest 'bruise' trial above it failed to converge instead of
    bruising (then the fruit bruises somewhere above ``max_force``, not at it); 'grip
    not reached' when that trial's grip stayed below its command, undamaged (the
    fingers deliver no more); None without a finite ``max_force`` or a trial above it."""
    nearest = bruise_trial_above(max_force, trials)
    if nearest is None:
        return None
    if nearest.outcome == SOLVER_FAILED:
        return 'solver failure'
    return 'bruise' if nearest.bruised or nearest.reached else 'grip not reached'


def lower_bound_limited_by(min_force: float | None, trials: Iterable[Trial]) -> str | None:
    """Why a window has no lower bound: 'grip not reached' when a 'hold' trial's grip
    stayed below its command (the hold search stopped below it: the fingers deliver no
    more); 'solver failure' when the largest force tried failed to converge (whether it
    holds is not known); 'gripper.max_force' when every force up to it was tried; None
    when ``min_force`` was found."""
    if min_force is not None:
        return None
    hold = [t for t in trials if t.kind == 'hold']
    if not all(t.reached for t in hold):
        return 'grip not reached'
    if hold and max(hold, key=lambda t: t.force).outcome == SOLVER_FAILED:
        return 'solver failure'
    return 'gripper.max_force'


def reach_bracket(trials: Iterable[Trial]) -> tuple[Trial | None, Trial | None]:
    """The 'hold' trials that end a hold search stopped by the fingers' reach: the
    largest reached force that did not hold (None if none) and the smallest force whose
    grip was not reached (None if none)."""
    hold = [t for t in trials if t.kind == 'hold']
    slid = [t for t in hold if t.reached and not t.held]
    unreached = [t for t in hold if not t.reached]
    return (max(slid, key=lambda t: t.force) if slid else None,
            min(unreached, key=lambda t: t.force) if unreached else None)


def estimates(config: Mapping[str, Any]) -> tuple[float, float, float]:
    """(m g / (2 mu_s) in N, the Hertz bruise force in N, the mass in kg).

    The Hertz radius is from the 2D outline where it meets the jaws (radius of
    curvature R in the x-z plane; for a planar contact R_e = R). In 3D (``dimension``
    3) the mass is the 3D fruit's and R_e = sqrt(R R_y), R_y = b^2 / a the radius of
    curvature along y at the jaw contact of a body of half-widths a (x) and b (y)
    (exact for spheroids: R_y = a for a body of revolution about z).
    """
    fruit = build_fruit(config)
    mass = fruit.total_mass
    radius_y = None
    if int(config.get('dimension', 2)) == 3:
        body = build_fruit3d(config)
        mass = body.total_mass
        half = 0.5 * np.ptp(body.rest_positions[body.surface], axis=0)
        radius_y = float(half[1] ** 2 / half[0])
    mu = config['contact.jaw.static_friction']
    if config['gripper.finger.pad.enabled']:
        mu = config['contact.pad.friction']
    weight = mass * config['world.gravity']
    hold = weight / (2 * mu) if mu > 0 else math.inf
    # the outline's radius of curvature where it meets the jaws (the points of largest |x|)
    surface = fruit.rest_positions[fruit.surface]
    radius = _outline_radius(surface, int(abs(surface[:, 0]).argmax()), fruit.rest_width)
    pad = config['gripper.finger.pad.enabled']
    e_star = contact_modulus(config['fruit.flesh.youngs_modulus'],
                             config['fruit.flesh.poisson_ratio'],
                             config['gripper.finger.pad.youngs_modulus'] if pad else None,
                             config['gripper.finger.pad.poisson_ratio'])
    in_plane = radius
    if config['gripper.finger.type'] == 'arc':  # a concave face conforms: 1/R - 1/Rf
        in_plane = 1.0 / max(1.0 / radius - 1.0 / config['gripper.finger.radius'],
                             1e-3 / radius)
    re = math.sqrt(in_plane * (radius if radius_y is None else radius_y))
    p_b = config['fruit.bruise_pressure']
    bruise = p_b ** 3 * math.pi ** 3 * re ** 2 / (6 * e_star ** 2)
    if config['gripper.finger.type'] == 'vgroove':  # two flanks share a jaw's force
        bruise *= 2 * math.sin(math.radians(0.5 * config['gripper.finger.groove_angle']))
    return hold, bruise, mass


def _outline_radius(surface: np.ndarray, i: int, width: float) -> float:
    """m, the radius of curvature of the closed outline ``surface`` (n, 2) at node ``i``
    (the circle through it and its neighbours; half ``width`` where they are in line)."""
    n = len(surface)
    a, b, c = surface[(i - 1) % n], surface[i], surface[(i + 1) % n]
    side = [math.dist(a, b), math.dist(b, c), math.dist(a, c)]
    area2 = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    return side[0] * side[1] * side[2] / (2 * area2) if area2 > 0 else 0.5 * width


def table_bruise_load(config: Mapping[str, Any]) -> float:
    """N, the load on the rigid table at which the fruit resting on it bruises: the
    Hertz force F = p_b^3 pi^3 Re^2 / (6 E*^2) with the rigid E* and the outline's
    radius of curvature at its lowest point (a round fruit: Re = R; validation.md
    section 3). Gripping a fruit that rests on the table loads the table too: a squeezed
    fruit bulges down against jaws that hold it by friction, so with a soft pad (which
    spares the jaw contact) the table contact may bruise first."""
    fruit = build_fruit(config)
    surface = fruit.rest_positions[fruit.surface]
    radius = _outline_radius(surface, int(surface[:, -1].argmin()), fruit.rest_width)
    e_star = contact_modulus(config['fruit.flesh.youngs_modulus'],
                             config['fruit.flesh.poisson_ratio'])
    return config['fruit.bruise_pressure'] ** 3 * math.pi ** 3 * radius ** 2 / (6 * e_star ** 2)


def trial_setup(config: Mapping[str, Any], scenario: Scenario) -> tuple[dict, Scenario]:
    """The configuration and scenario of a window trial: the jaws start open at the
    grasp height (the scenario's approach skipped)."""
    config = dict(config)
    lift = scenario['approach.height']
    if config.get('gripper.initial_lift') is not None:
        config['gripper.initial_lift'] = config['gripper.initial_lift'] - lift
    return config, scenario.with_values(approach__height=0.0)


def evaluate_grasp(config: Mapping[str, Any], scenario: Scenario, force: float,
                   kind: str = 'hold') -> GraspEvaluation:
    """One grasp at ``force`` N: a fresh simulation of ``config`` (from ``trial_setup``)
    runs the scenario's close, squeeze, lift, transport and a hold of ``squeeze.time``.

    kind: 'hold' runs to the end; 'bruise' stops as soon as the fruit is damaged.
    """
    if kind not in ('hold', 'bruise'):
        raise ValueError(f'unknown trial kind {kind!r}')
    sim = make_simulation(config)
    machine = PickAndPlace(sim, scenario.with_values(close__mode='force', close__force=force),
                           until='transport', stop_on_bruise=(kind == 'bruise'))
    return evaluate(sim, machine, force)


def trial_of(evaluation: GraspEvaluation, kind: str, wall_time: float = 0.0) -> Trial:
    """The window's verdict on an evaluation: held (for 'hold': ``evaluation.held``,
    carried with less than ``window.max_slip`` of slip) or damaged (bruised or crushed,
    for 'bruise'; such a run stopped at the damage, so it counts as not held)."""
    held, bruised = evaluation.held, evaluation.bruised
    if kind == 'bruise' and (evaluation.bruised or evaluation.crushed):
        held, bruised = False, True
    return Trial(force=float(evaluation.force), kind=kind, held=bool(held),
                 slipped=not held, bruised=bool(bruised), outcome=evaluation.outcome,
                 slip_distance=float(evaluation.slip_distance),
                 peak_grip_force=float(evaluation.peak_grip_force),
                 peak_jaw_pressure=float(evaluation.peak_jaw_pressure),
                 peak_table_pressure=float(evaluation.peak_table_pressure),
                 peak_damage_pressure=float(evaluation.peak_damage_pressure),
                 bruised_at=evaluation.bruised_at or None, wall_time=wall_time)


def measured_bounds(min_force: float | None, max_force: float | None,
                    trials: Iterable[Trial]) -> tuple[float | None, float | None]:
    """(N, N) the peak grip force measured in the trial of each bound: the 'hold' trial
    at ``min_force`` and the 'bruise' trial at ``max_force`` (None where a bound is None
    or inf)."""
    def measured(kind: str, force: float | None) -> float | None:
        if force is None or math.isinf(force):
            return None
        found = [t.peak_grip_force for t in trials if t.kind == kind and t.force == force]
        return found[0] if found else None
    trials = list(trials)
    return measured('hold', min_force), measured('bruise', max_force)


def window_bisections(config: Mapping[str, Any], hold_estimate: float,
                      bruise_estimate: float, tolerance: float = TOLERANCE) -> list[Search]:
    """The grasp window's two bisections, independent of each other: the smallest force
    that holds ('hold', verdict ``hold_verdict``: a grip the fingers do not reach ends
    the search upward) and the largest that does not bruise ('bruise', verdict
    ``Trial.safe``).

    Args:
        config: the trials' configuration (friction, pad, gripper.max_force, dimension).
        hold_estimate, bruise_estimate: N, the closed-form seeds of ``estimates``.
        tolerance: relative width at which a bisection stops.
    """
    limit = float(config['gripper.max_force'])
    pad = config['gripper.finger.pad.enabled']
    mu = config['contact.pad.friction'] if pad else config['contact.jaw.static_friction']
    # a slide that starts (e.g. as the table lets go) goes on at kinetic friction: the
    # minimum lies between m g / (2 mu_s) and m g / (2 mu_k)
    mu_k = mu if pad else config['contact.jaw.kinetic_friction']
    kinetic = hold_estimate * mu / mu_k if mu_k > 0 else 2 * hold_estimate
    # the pressurised 3D shell spreads its contact (its pressure stays near the turgor,
    # far from Hertz): start the search no lower than the holding force there
    seed = (max(bruise_estimate, hold_estimate) if int(config.get('dimension', 2)) == 3
            else bruise_estimate)
    return [Search('hold', lambda: bisection(0.8 * hold_estimate, 1.15 * kinetic, limit,
                                             tolerance, want_smallest=True),
                   hold_verdict, (True, False, OUT_OF_REACH)),
            Search('bruise', lambda: bisection(0.8 * seed, 1.25 * seed, limit, tolerance,
                                               want_smallest=False),
                   lambda trial: trial.safe)]


def window_search(config: Mapping[str, Any], hold_estimate: float, bruise_estimate: float,
                  tolerance: float = TOLERANCE
                  ) -> Generator[Request, Trial, tuple[float | None, float | None]]:
    """The grasp window's two bisections (``window_bisections``) one after the other as a
    generator: it yields ``(kind, force)`` requests, is sent back each request's
    ``Trial`` (``trial_of``), and returns ``(min_force, max_force)`` (see
    ``GraspWindow``). The same search runs in one process (``grasp_window``) and over a
    cluster (``gripper_sim.workflows.study``)."""
    hold, bruise = window_bisections(config, hold_estimate, bruise_estimate, tolerance)
    min_force = yield from _ask(hold)
    max_force = yield from _ask(bruise)
    return min_force, max_force


def _ask(search: Search) -> Generator[Request, Trial, float | None]:
    """Turn a bisection's forces into ``(kind, force)`` requests and trials into its
    verdicts."""
    bisect = search.bisection()
    try:
        force = next(bisect)
        while True:
            trial = yield search.kind, force
            force = bisect.send(search.verdict(trial))
    except StopIteration as stop:
        return stop.value


def run_search(search: Generator, answer: Callable[[Any], Any]) -> Any:
    """Drive a search generator in this process: send ``answer(request)`` for each
    request it yields; its return value."""
    try:
        request = next(search)
        while True:
            request = search.send(answer(request))
    except StopIteration as stop:
        return stop.value


def run_trial(config: Mapping[str, Any], scenario: Scenario, request: Request) -> Trial:
    """The window's trial of ``request`` (kind, force N): ``evaluate_grasp`` and its
    verdict (``trial_of``), with its wall time."""
    kind, force = request
    start = time.perf_counter()
    return trial_of(evaluate_grasp(config, scenario, force, kind), kind,
                    time.perf_counter() - start)


def grasp_window(config: Mapping[str, Any], scenario: Scenario,
                 tolerance: float = TOLERANCE,
                 progress: Callable[[Trial], None] | None = None,
                 workers: int = 1) -> GraspWindow:
    """Find the grasp window of the fruit and finger of ``config`` in ``scenario``.

    Args:
        config: the configuration of the runs (``scenario.scenario_config``).
        scenario: gives the close speed, squeeze time, lift and transport.
        tolerance: relative width at which a bisection stops.
        progress: called with each trial of the searches' paths, in their order, as it
            is known (with ``workers`` > 1 a trial run ahead waits for the verdicts before
            it, one the searches did not need is not reported).
        workers: processes running trials; above 1 the two bisections run side by side
            and look ahead (``workflows.speculative``): the same trials and window as
            one, sooner.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise GripperSimError(f'workers must be a whole number >= 1, got {workers!r}')
    start = time.perf_counter()
    hold_estimate, bruise_estimate, mass = estimates(config)
    config, base = trial_setup(config, scenario)
    searches = window_bisections(config, hold_estimate, bruise_estimate, tolerance)
    pool = (InlinePool(run_trial, (config, base)) if workers == 1
            else ProcessPool(workers, run_trial, (config, base)))
    with pool:
        run = run_searches(searches, pool, workers, progress)
    (min_force, max_force), trials = run.answers, run.paths[0] + run.paths[1]
    mu = (config['contact.pad.friction'] if config['gripper.finger.pad.enabled']
          else config['contact.jaw.static_friction'])
    low, high = measured_bounds(min_force, max_force, trials)
    return GraspWindow(fruit=str(config['fruit.name']), finger=str(config['gripper.finger.name']),
                       min_force=min_force, max_force=max_force, min_estimate=hold_estimate,
                       max_estimate=bruise_estimate, mass=mass, friction=mu,
                       tolerance=tolerance, trials=trials,
                       wall_time=time.perf_counter() - start,
                       max_slip=float(config['window.max_slip']),
                       table_bruise_estimate=(table_bruise_load(config)
                                              if config['world.table'] else 0.0),
                       min_force_measured=low, max_force_measured=high, workers=workers,
                       look_ahead_trials=run.wasted)


def _bisect(ok: Callable[[float], bool], low: float, high: float, limit: float,
            tolerance: float, want_smallest: bool) -> float | None:
    """``bisection`` driven in this process by the verdicts of ``ok(force)``."""
    return run_search(bisection(low, high, limit, tolerance, want_smallest), ok)


def bisection(low: float, high: float, limit: float, tolerance: float,
              want_smallest: bool) -> Generator[float, bool | str, float | None]:
    """The boundary of the forces where a verdict holds, to ``tolerance``, from the
    bracket guess [low, high] (widened as needed: halved down at most ``MAX_WIDENINGS``
    times, doubled up until ``limit``, so "none up to ``limit``" means ``limit`` was tried).
    A generator: yields the force (N) to try next, is sent back the verdict there: True
    (ok), False, or (``want_smallest`` only) ``OUT_OF_REACH``: not ok, and no force above
    it can be, so the search looks for an ok force below it, between the largest force
    found not ok and the smallest out of reach, until they are within ``tolerance``.

    want_smallest: the verdict holds above the boundary (the minimum force); returns the
    smallest force found ok, None if none up to ``limit`` (or below the reach). Otherwise
    it holds below it (the maximum force); returns the largest force found ok, ``inf`` if
    ok at ``limit``, None if not even at the smallest force tried.
    """
    if not low > 0 or not math.isfinite(high):
        raise GripperSimError('the grasp window needs a positive, finite force estimate')
    lo, hi = min(low, limit), min(high, limit)
    if lo >= hi:
        lo = 0.8 * hi
    good_high = want_smallest
    reach = math.inf  # the smallest force found out of reach
    # widen until ok(lo) != ok(hi) with the good side where it should be
    for _ in range(MAX_WIDENINGS):
        ok_lo = yield lo
        if ok_lo == OUT_OF_REACH:  # not even lo is reached: look below it
            reach, lo = lo, lo / 2
            continue
        if ok_lo == good_high:  # lo is already on the high side: move it down
            hi, lo = lo, lo / 2
            reach = math.inf  # an ok force below the reach brackets the search itself
            continue
        break
    else:  # ok at every force tried down there: the smallest of them (hi), or none
        return hi if want_smallest and reach == math.inf else None
    while reach == math.inf:  # doubling, so at most log2(limit / hi) + 1 trials
        ok_hi = yield hi
        if ok_hi == OUT_OF_REACH:
            reach = hi
        elif ok_hi != good_high:  # hi is still on the low side: move it up
            if hi >= limit:
                return None if want_smallest else math.inf
            lo, hi = hi, min(2 * hi, limit)
        else:
            break
    while reach < math.inf:  # below the reach: an ok force, or none within tolerance
        if (reach - lo) <= tolerance * reach:
            return None
        mid = 0.5 * (lo + reach)
        verdict = yield mid
        if verdict == OUT_OF_REACH:
            reach = mid
        elif verdict == good_high:
            hi = mid
            break
        else:
            lo = mid
    while (hi - lo) > tolerance * hi:
        mid = 0.5 * (lo + hi)
        if (yield mid) == good_high:
            hi = mid
        else:
            lo = mid
    return hi if want_smallest else lo
