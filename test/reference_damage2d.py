"""Numpy reference of the 2D damage rule, for the tests only.

The simulation applies the rule of ``gripper_sim.core.damage`` (its module docstring)
with one numba function, ``damage_patches``, on both routes (``DamageTracker.update``
and the compiled step). This is the same rule written again in numpy, so that the tests
can check the compiled one against an independent version (equal to round-off).

Each function takes a ``DamageTracker`` for its rest data (face table, rest curvature,
moduli, depth, bruise pressure) and leaves the tracker as it is.
"""
from __future__ import annotations

import math

import numpy as np

from gripper_sim.core.damage import RESOLVED_NODES, Contact, hertz


def runs(tracker, obstacle_of_surface: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Runs of consecutive outline positions held by one body: (body, positions)."""
    n = len(obstacle_of_surface)
    body = np.array([tracker.groups[o] if o >= 0 else -1 for o in obstacle_of_surface])
    if not np.any(body >= 0):
        return []
    if np.all(body == body[0]):
        return [(int(body[0]), np.arange(n))]
    start = int(np.flatnonzero(body != np.roll(body, 1))[0])  # where the body changes
    out, current, positions = [], None, []
    for k in range(n):
        i = (start + k) % n
        if body[i] != current:
            if current is not None and current >= 0:
                out.append((current, np.array(positions)))
            current, positions = body[i], []
        positions.append(i)
    if current is not None and current >= 0:
        out.append((current, np.array(positions)))
    return out


def contacts(tracker, positions: np.ndarray, normal_force: np.ndarray,
             obstacle: np.ndarray) -> list[tuple[Contact, np.ndarray, int]]:
    """The contact patches: (Contact, outline positions of its nodes, the position
    nearest its centre)."""
    ring = tracker.ring
    seg = np.linalg.norm(np.roll(positions[ring], -1, axis=0) - positions[ring], axis=1)
    out = []
    for body, run in runs(tracker, obstacle[ring]):
        nodes = ring[run]
        f = np.maximum(normal_force[nodes], 0.0)
        load = float(f.sum())
        if load <= 0:
            continue
        centre = (f @ positions[nodes]) / load
        near = run[int(np.argmin(np.linalg.norm(positions[nodes] - centre, axis=1)))]
        k1 = float(tracker.rest_curvature[near])
        if k1 <= 0:
            k1 = 1e-3
        faces = obstacle[nodes]
        padded = np.mean([tracker.padded[o] for o in faces]) >= 0.5
        modulus = tracker.pad_modulus if padded else tracker.rigid_modulus
        if (np.mean([tracker.deformable[o] for o in faces]) >= 0.5
                and load ** 2 / float(f @ f) >= RESOLVED_NODES):
            arc = np.concatenate([[0.0], np.cumsum(seg[run[:-1]])])  # along the run
            mean = float(f @ arc) / load
            variance = float(f @ (arc - mean) ** 2) / load
            k1_eff = load / tracker.depth / (math.pi * modulus * variance)
        else:
            face_k = float(np.mean([tracker.curvature[o] for o in faces]))
            k1_eff = max(k1 + face_k, 1e-3 * k1)
        re = 1.0 / math.sqrt(k1_eff * k1)
        a, p0 = hertz(load, re, modulus)
        out.append((Contact(body, load, centre, a, p0, re, modulus), run, near))
    return out


def cover(x: np.ndarray, near: int, centre: np.ndarray, radius: float) -> np.ndarray:
    """(n_s,) m, each outline position's share (half the segments either side) within
    ``radius`` (m, along the outline) of ``centre``; x (n_s, 2) m the outline."""
    n = len(x)
    seg = np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)
    rel = np.zeros(n)
    ahead = n // 2
    idx = (near + 1 + np.arange(ahead)) % n
    rel[idx] = np.cumsum(seg[(near + np.arange(ahead)) % n])
    idx = (near - 1 - np.arange(n - 1 - ahead)) % n
    rel[idx] = -np.cumsum(seg[idx])
    tangent = x[(near + 1) % n] - x[(near - 1) % n]
    tangent = tangent / max(float(np.linalg.norm(tangent)), 1e-300)
    offset = float((centre - x[near]) @ tangent)
    lo, hi = rel - 0.5 * np.roll(seg, 1), rel + 0.5 * seg
    return np.clip(np.minimum(hi, offset + radius) - np.maximum(lo, offset - radius), 0.0, None)


def step(tracker, covered: np.ndarray, positions: np.ndarray, normal_force: np.ndarray,
         obstacle: np.ndarray):
    """One step of the rule from the bruised cover ``covered`` (n_s,) m: (contacts,
    node pressure (n_s,) Pa, largest peak pressure Pa, the new cover (n_s,) m)."""
    ring = tracker.ring
    x = positions[ring]
    node_pressure = np.zeros(len(ring))
    covered = covered.copy()
    patches = contacts(tracker, positions, normal_force, obstacle)
    for contact, run, near in patches:
        a, p0 = contact.radius, contact.peak_pressure
        s = np.linalg.norm(x[run] - contact.centre, axis=1)
        node_pressure[run] = p0 * np.sqrt(np.maximum(0.0, 1.0 - (s / a) ** 2))
        if p0 > tracker.bruise_pressure and len(ring) >= 3:
            radius = a * math.sqrt(1.0 - (tracker.bruise_pressure / p0) ** 2)
            covered = np.maximum(covered, cover(x, near, contact.centre, radius))
    pressure = max((c.peak_pressure for c, _, _ in patches), default=0.0)
    return [c for c, _, _ in patches], node_pressure, pressure, covered
