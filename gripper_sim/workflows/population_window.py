"""The population window: the grip forces that succeed for a fraction of a population.

Input: each fruit's own window [min_i, max_i] (N): min_i the smallest force that holds
it (None: none up to gripper.max_force), max_i the largest that leaves it undamaged
(None: damaged at every force tried; inf: undamaged up to gripper.max_force, counted
as gripper.max_force). A force F succeeds for fruit i when min_i <= F <= max_i, so the
success fraction p(F) of the sample is a step function that changes only at the
min_i and max_i.

- ``window``: the forces where p(F) >= fraction (default 0.99), as [low, high]
  (the smallest and largest such force; "no safe force" when there is none).
- ``ci``: a bootstrap percentile interval (over resamples of the fruits, seeded) of
  each end, at ``confidence``; ``no_window_share`` is the share of resamples without a
  window. A bootstrap cannot see past the sample's extreme fruits: at fraction 0.99
  with 100 fruits the ends are the extreme fruits' forces.
- ``confident_window``: the forces where the one-sided Clopper-Pearson lower bound of
  the success probability at ``confidence`` is >= fraction: a claim that holds for
  the whole population, not just the sample. With no failure at all it needs at least
  ln(1 - confidence) / ln(fraction) fruits (299 for 0.99 at 95 %).
- ``curve``: p(F) and its two-sided Clopper-Pearson interval on a force grid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.stats import beta

#: bootstrap resamples of the confidence interval
BOOTSTRAP = 2000


@dataclass(frozen=True)
class SampleWindow:
    """One fruit's window (N; see the module docstring for None and inf);
    ``max_force_limited_by``: 'solver failure' where the trial above ``max_force`` did not
    converge (the fruit bruises somewhere above it), 'grip not reached' where its grip
    stayed below its command (the fingers deliver no more), 'bruise', or None
    (unknown); ``min_force_limited_by``: where ``min_force`` is None, 'grip not reached'
    when nothing held below a force whose grip was not reached, 'solver failure' when
    the trial at the largest force did not converge, else 'gripper.max_force' (None: a
    min_force, or unknown)."""

    sample: int
    min_force: float | None
    max_force: float | None
    max_force_limited_by: str | None = None
    min_force_limited_by: str | None = None

    @property
    def exists(self) -> bool:
        return (self.min_force is not None and self.max_force is not None
                and self.min_force <= self.max_force)


def success_matrix(windows: Sequence[SampleWindow], forces: np.ndarray) -> np.ndarray:
    """(n_samples, n_forces) bool: force j succeeds for fruit i."""
    low = np.array([w.min_force if w.exists else np.inf for w in windows], dtype=float)
    high = np.array([w.max_force if w.exists else -np.inf for w in windows], dtype=float)
    return (forces[None, :] >= low[:, None]) & (forces[None, :] <= high[:, None])


def candidate_forces(windows: Sequence[SampleWindow], limit: float) -> np.ndarray:
    """The forces (N, sorted) where p(F) can change: every finite end, and ``limit``."""
    ends = [limit]
    for w in windows:
        if w.exists:
            ends.append(w.min_force)
            ends.append(min(w.max_force, limit))
    return np.unique(np.asarray(ends, dtype=float))


def _ends(p: np.ndarray, forces: np.ndarray, fraction: float) -> tuple[float, float] | None:
    ok = p >= fraction - 1e-12
    if not np.any(ok):
        return None
    return float(forces[np.argmax(ok)]), float(forces[len(ok) - 1 - np.argmax(ok[::-1])])


def clopper_pearson(successes: np.ndarray, n: int, confidence: float,
                    two_sided: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Exact binomial interval of the success probability: (lower, upper), each shaped
    like ``successes``. One-sided: the lower bound at ``confidence`` (upper = 1)."""
    k = np.asarray(successes, dtype=float)
    alpha = 1.0 - confidence
    tail = alpha / 2 if two_sided else alpha
    with np.errstate(invalid='ignore'):
        lower = np.where(k > 0, beta.ppf(tail, k, n - k + 1), 0.0)
        upper = np.where(k < n, beta.ppf(1 - tail, k + 1, n - k), 1.0)
    return lower, (upper if two_sided else np.ones_like(lower))


def population_window(windows: Sequence[SampleWindow], limit: float, fraction: float,
                      confidence: float, seed: int = 0, curve_points: int = 120) -> dict:
    """The population window of ``windows`` (see the module docstring), JSON-ready.

    Args:
        windows: one per fruit.
        limit: N, gripper.max_force (a fruit undamaged there counts as safe up to it).
        fraction: share of the population that must succeed, in (0, 1).
        confidence: level of the intervals, in (0, 1).
        seed: of the bootstrap.
        curve_points: forces of the success curve (log-spaced, plus every end).
    """
    n = len(windows)
    forces = candidate_forces(windows, limit)
    matrix = success_matrix(windows, forces)
    p = matrix.mean(axis=0) if n else np.zeros(len(forces))
    ends = _ends(p, forces, fraction)
    result: dict = dict(fraction=fraction, confidence=confidence, samples=n,
                        holds_nowhere=sum(w.min_force is None for w in windows),
                        grip_limit_holds_nowhere=sum(
                            w.min_force_limited_by == 'grip not reached' for w in windows),
                        solver_failure_holds_nowhere=sum(
                            w.min_force_limited_by == 'solver failure' for w in windows),
                        damaged_everywhere=sum(w.max_force is None for w in windows),
                        no_own_window=sum(not w.exists for w in windows),
                        solver_failure_bounds=sum(w.max_force_limited_by == 'solver failure'
                                                  for w in windows),
                        grip_limit_bounds=sum(w.max_force_limited_by == 'grip not reached'
                                              for w in windows),
                        window=None, ci=None, no_window_share=None,
                        confident_window=None)
    if ends is not None:
        result['window'] = dict(low=ends[0], high=ends[1],
                                high_is_limit=bool(ends[1] >= limit))
    if n:
        rng = np.random.default_rng(seed)
        weights = rng.multinomial(n, np.full(n, 1.0 / n), size=BOOTSTRAP) / n
        boot = weights @ matrix  # (BOOTSTRAP, n_forces)
        lows, highs = [], []
        for row in boot:
            found = _ends(row, forces, fraction)
            if found is not None:
                lows.append(found[0])
                highs.append(found[1])
        result['no_window_share'] = 1.0 - len(lows) / BOOTSTRAP
        if lows:
            q = [50 * (1 - confidence), 50 * (1 + confidence)]
            result['ci'] = dict(low=[float(v) for v in np.percentile(lows, q)],
                                high=[float(v) for v in np.percentile(highs, q)])
        lower, _ = clopper_pearson(matrix.sum(axis=0), n, confidence, two_sided=False)
        sure = _ends(lower, forces, fraction)
        if sure is not None:
            result['confident_window'] = dict(low=sure[0], high=sure[1])
    result['samples_needed'] = int(math.ceil(math.log(1 - confidence) / math.log(fraction)))
    result['curve'] = success_curve(windows, limit, confidence, curve_points)
    return result


def success_curve(windows: Sequence[SampleWindow], limit: float, confidence: float,
                  points: int = 120) -> dict:
    """p(F) on log-spaced forces from half the smallest finite bound of a fruit to twice
    the largest (capped at ``limit``; the bounds of fruits without a window of their own
    count, so that a population with none still gets the forces that were tried), with
    every end included: {force, p, lower, upper}."""
    n = len(windows)
    ends = candidate_forces(windows, limit)
    bounds = np.array([b for w in windows for b in (w.min_force, w.max_force)
                       if b is not None and b < limit], dtype=float)
    finite = bounds if bounds.size else ends
    start, stop = 0.5 * float(finite.min()), min(2.0 * float(finite.max()), limit)
    grid = np.geomspace(start, max(stop, 1.01 * start), points)
    forces = np.unique(np.concatenate([grid, ends[(ends >= start) & (ends <= stop)]]))
    matrix = success_matrix(windows, forces)
    k = matrix.sum(axis=0)
    lower, upper = clopper_pearson(k, max(n, 1), confidence)
    return dict(force=forces.tolist(), p=(k / max(n, 1)).tolist(), lower=lower.tolist(),
                upper=upper.tolist())


def grid_curve(successes: np.ndarray, forces: Sequence[float], confidence: float) -> dict:
    """p(F) at the grid forces from (n_samples, n_forces) successes, with intervals."""
    n = successes.shape[0]
    k = successes.sum(axis=0)
    lower, upper = clopper_pearson(k, max(n, 1), confidence)
    return dict(force=[float(f) for f in forces], p=(k / max(n, 1)).tolist(),
                lower=lower.tolist(), upper=upper.tolist())
