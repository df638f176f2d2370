"""The grasp window: the grip forces that hold a fruit without bruising it, by simulation.

- Minimum force: the smallest grip force at which the fruit is carried through the
  scenario's close, squeeze, lift, transport and a hold (``squeeze.time``): not
  dropped (``scenario.DROP_SLIP``) and no longer sliding in the jaws at the end. The
  slip it took on the way (e.g. at lift-off, when the table lets go and the grip force
  dips for a moment) is reported with each trial. Found by bisection
  over full simulations, from a bracket seeded with the rigid-flat-jaw estimate
  m g / (2 mu_s) (validation.md section 6) and m g / (2 mu_k), widened until it
  brackets.
- Maximum force: the largest grip force at which the same run leaves the fruit
  undamaged (neither bruised nor crushed), by bisection seeded with the Hertz force at
  which the peak pressure reaches the bruise threshold,
  F = p_b^3 pi^3 R^2 / (6 E*^2) (validation.md section 3).
- The window is [minimum, maximum] when minimum <= maximum, else there is none.

Each trial is a fresh simulation starting with the jaws open at the grasp height (the
scenario's approach skipped). A trial stops early once its answer is known (dropped or
bruised). A trial whose solver fails (``ConvergenceError``) counts as neither holding
nor safe, so that force stays out of the window.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from gripper_sim.core.damage import contact_modulus
from gripper_sim.core.scenario import Scenario, run_scenario
from gripper_sim.errors import ConvergenceError, GripperSimError

#: relative width of the final bisection brackets
TOLERANCE = 0.03
#: how many times a bracket end may be halved or doubled looking for a bracket
MAX_WIDENINGS = 8


@dataclass
class Trial:
    """One simulated grasp: the force (N), what happened and the run's measures."""

    force: float
    held: bool
    bruised: bool
    outcome: str
    slip_distance: float
    peak_pressure: float
    wall_time: float


@dataclass
class GraspWindow:
    """Result of ``grasp_window``.

    Attributes:
        min_force: N, smallest force that held (None: none up to gripper.max_force).
        max_force: N, largest force that did not bruise (None: even the smallest force
            tried bruised; inf: nothing bruised up to gripper.max_force).
        min_estimate, max_estimate: N, the closed-form seeds (m g / 2 mu; Hertz).
        trials: every simulated grasp, in order.
        wall_time: s, time to compute the window.
        min_force_no_slip: N, the smallest force tried that held with less than
            ``scenario.SLIP_TOLERANCE`` of slip (an upper bound, not bisected), or None.
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
    min_force_no_slip: float | None = None

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
                    wall_time=self.wall_time, min_force_no_slip=self.min_force_no_slip,
                    trials=[vars(t) for t in self.trials])


def estimates(config: Mapping[str, Any]) -> tuple[float, float, float]:
    """(m g / (2 mu_s) in N, the Hertz bruise force in N, the mass in kg).

    The Hertz radius is from the 2D outline where it meets the jaws (radius of
    curvature R in the x-z plane; for a planar contact R_e = R). In 3D (``dimension``
    3) the mass is the 3D fruit's and R_e = sqrt(R R_y), R_y = b^2 / a the radius of
    curvature along y at the jaw contact of a body of half-widths a (x) and b (y)
    (exact for spheroids: R_y = a for a body of revolution about z).
    """
    from gripper_sim.core.fruit import build_fruit
    fruit = build_fruit(config)
    mass = fruit.total_mass
    radius_y = None
    if int(config.get('dimension', 2)) == 3:
        from gripper_sim.core3d.fruit import build_fruit3d
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
    i = int(abs(surface[:, 0]).argmax())
    n = len(surface)
    a, b, c = surface[(i - 1) % n], surface[i], surface[(i + 1) % n]
    side = [math.dist(a, b), math.dist(b, c), math.dist(a, c)]
    area2 = abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    radius = side[0] * side[1] * side[2] / (2 * area2) if area2 > 0 else 0.5 * fruit.rest_width
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


def grasp_window(config: Mapping[str, Any], scenario: Scenario,
                 tolerance: float = TOLERANCE,
                 progress: Callable[[Trial], None] | None = None) -> GraspWindow:
    """Find the grasp window of the fruit and finger of ``config`` in ``scenario``.

    Args:
        config: the configuration of the runs (``scenario.scenario_config``).
        scenario: gives the close speed, squeeze time, lift and transport.
        tolerance: relative width at which a bisection stops.
        progress: called with each trial as it finishes.
    """
    from gripper_sim.core import make_simulation as Simulation
    start = time.perf_counter()
    config = dict(config)
    limit = float(config['gripper.max_force'])
    hold_estimate, bruise_estimate, mass = estimates(config)
    lift = scenario['approach.height']
    config['gripper.initial_lift'] = config['gripper.initial_lift'] - lift \
        if config.get('gripper.initial_lift') is not None else None
    base = scenario.with_values(approach__height=0.0)
    trials: list[Trial] = []
    cache: dict[tuple[str, float], Trial] = {}

    def trial(force: float, kind: str) -> Trial:
        key = (kind, round(force, 12))
        if key in cache:
            return cache[key]
        t0 = time.perf_counter()
        sim = Simulation(config)
        try:
            run = run_scenario(sim, base.with_values(close__mode='force', close__force=force),
                               until='transport', stop_on_bruise=(kind == 'bruise'))
        except ConvergenceError as err:
            # a force the solver cannot follow is kept out of the window: not held, and
            # counted as damaging
            run = dict(outcome='solver failed', dropped=True, sliding=True, bruised=True,
                       slip_distance=0.0, damage=None, message=str(err))
        damage = run['damage'] or {}
        held = (run['outcome'] in ('held', 'slipped', 'bruised', 'crushed')
                and not run['dropped'] and not run['sliding'])
        result = Trial(force=float(force), held=bool(held), bruised=bool(run['bruised']),
                       outcome=str(run['outcome']), slip_distance=float(run['slip_distance']),
                       peak_pressure=float(damage.get('peak_pressure', 0.0)),
                       wall_time=time.perf_counter() - t0)
        if kind == 'bruise' and (result.bruised or run.get('crushed')):
            result.bruised = True  # damaged: bruised, or crushed without a bruise
            result.held = False  # stopped at the damage: holding was not tried to the end
        cache[key] = result
        trials.append(result)
        if progress is not None:
            progress(result)
        return result

    mu = (config['contact.pad.friction'] if config['gripper.finger.pad.enabled']
          else config['contact.jaw.static_friction'])
    # a slide that starts (e.g. as the table lets go) goes on at kinetic friction: the
    # minimum lies between m g / (2 mu_s) and m g / (2 mu_k)
    mu_k = (mu if config['gripper.finger.pad.enabled']
            else config['contact.jaw.kinetic_friction'])
    kinetic = hold_estimate * mu / mu_k if mu_k > 0 else 2 * hold_estimate
    min_force = _bisect(lambda f: trial(f, 'hold').held, 0.8 * hold_estimate,
                        1.15 * kinetic, limit, tolerance, want_smallest=True)
    # the pressurised 3D shell spreads its contact (its pressure stays near the turgor,
    # far from Hertz): start the search no lower than the holding force there
    seed = (max(bruise_estimate, hold_estimate) if int(config.get('dimension', 2)) == 3
            else bruise_estimate)
    max_force = _bisect(lambda f: not trial(f, 'bruise').bruised, 0.8 * seed, 1.25 * seed,
                        limit, tolerance, want_smallest=False)
    from gripper_sim.core.scenario import SLIP_TOLERANCE
    firm = [t.force for t in trials if t.held and t.slip_distance <= SLIP_TOLERANCE]
    return GraspWindow(fruit=str(config['fruit.name']), finger=str(config['gripper.finger.name']),
                       min_force=min_force, max_force=max_force, min_estimate=hold_estimate,
                       max_estimate=bruise_estimate, mass=mass, friction=mu,
                       tolerance=tolerance, trials=trials,
                       wall_time=time.perf_counter() - start,
                       min_force_no_slip=min(firm) if firm else None)


def _bisect(ok: Callable[[float], bool], low: float, high: float, limit: float,
            tolerance: float, want_smallest: bool) -> float | None:
    """The boundary of the forces where ``ok`` holds, to ``tolerance``, from the
    bracket guess [low, high] (widened as needed: halved down at most ``MAX_WIDENINGS``
    times, doubled up until ``limit``, so "none up to ``limit``" means ``limit`` was tried).

    want_smallest: ``ok`` holds above the boundary (the minimum force); returns the
    smallest force found ok, None if none up to ``limit``. Otherwise ``ok`` holds
    below it (the maximum force); returns the largest force found ok, ``inf`` if ok
    at ``limit``, None if not even at the smallest force tried.
    """
    if not low > 0 or not math.isfinite(high):
        raise GripperSimError('the grasp window needs a positive, finite force estimate')
    lo, hi = min(low, limit), min(high, limit)
    if lo >= hi:
        lo = 0.8 * hi
    good_high = want_smallest
    # widen until ok(lo) != ok(hi) with the good side where it should be
    for _ in range(MAX_WIDENINGS):
        ok_lo = ok(lo)
        if ok_lo == good_high:  # lo is already on the high side: move it down
            hi, lo = lo, lo / 2
            continue
        break
    else:
        return lo if want_smallest else None
    while True:  # doubling, so at most log2(limit / hi) + 1 trials
        ok_hi = ok(hi)
        if ok_hi != good_high:  # hi is still on the low side: move it up
            if hi >= limit:
                return None if want_smallest else math.inf
            lo, hi = hi, min(2 * hi, limit)
            continue
        break
    while (hi - lo) > tolerance * hi:
        mid = 0.5 * (lo + hi)
        if ok(mid) == good_high:
            hi = mid
        else:
            lo = mid
    return hi if want_smallest else lo
