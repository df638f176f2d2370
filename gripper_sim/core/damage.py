"""Damage of the fruit: bruising from contact pressure, crushing from flesh stress.

The planar model spreads a contact over the whole depth b, so its own line-contact
pressure (``Deformation.peak_contact_pressure``: node force over tributary length times
b) understates the pressure of a round fruit's small, round contact patch several
times. Damage therefore uses the Hertz reasoning of ASAE S368 on every contact the
simulation resolves (fruit-data.md, "Hertz-based bruise reasoning"; validation.md
section 3):

- a contact is a run of consecutive surface nodes held by the faces of one body (a
  jaw, the table); its normal load F (N) is the sum of the nodes' normal reactions
  (and, with a soft pad, the pad's pressure forces), its centre the load-weighted
  position;
- the fruit's principal radii there are the rest outline's in-plane radius of
  curvature R1 and, out of plane, the same (a round fruit); a concave face of radius
  Rf adds curvature -1/Rf in plane; equivalent radius Re = sqrt(R1' R2) (Johnson,
  Contact Mechanics, 1985, ch. 4);
- the contact modulus is E* = 1 / ((1 - nu^2) / E + (1 - nu_p^2) / E_p) with a soft pad
  or a deformable finger of E_p, nu_p (two elastic bodies, Hertz) and E / (1 - nu^2) on
  a rigid face;
- on a deformable finger (a Fin Ray, a solid pad) the in-plane radius is measured, not
  assumed: the simulation resolves how the finger yields and wraps in the plane, and
  shows it as the patch's width. R1' is the radius of the plane-strain Hertz contact with
  the patch's line load F' = F / b and its width: Hertz's pressure p(s) = p_l sqrt(1 -
  s^2 / a_l^2) has the load-weighted variance a_l^2 / 4 along the outline, so with the
  patch's own variance sigma^2 (of its node forces over their arc positions) a_l = 2
  sigma, p_l = F' / (pi sigma) and R1' = pi E* sigma^2 / F' (Johnson 1985, eqs.
  4.43-4.44). For two elastic half-planes that is the fruit's R1 again; a finger that
  wraps spreads the load, so R1' grows and p0 falls. The width and not the patch's
  largest node force over its tributary length: on the pressurised skin that peak
  sits where the skin bends round a finger's rib or the patch's end, narrower than any
  practical node spacing, and grew by 75 % from 64 to 512 outline nodes (the Fin Ray at
  8 N), where sigma moved by 3 %. A patch whose load rests on fewer than
  ``RESOLVED_NODES`` nodes (their effective count) has no resolved width: it keeps the
  fruit's rest radius, as on a rigid face (the higher, conservative p0);
- contact radius a = (3 F Re / (4 E*))^(1/3), peak pressure p0 = 3 F / (2 pi a^2), and
  pressure p(s) = p0 sqrt(1 - s^2 / a^2) at distance s from the centre: that is the
  per-node pressure reported;
- the fruit is bruised once p0 exceeds ``fruit.bruise_pressure``; the bruise covers
  the part of the patch above the threshold, s < a sqrt(1 - (p_b / p0)^2), and the
  bruised length accumulates over time (a bruise stays); its fraction is over the rest
  perimeter;
- flesh stress: the Tresca stress 2 tau_max = 0.62 p0 below the contact (tau_max =
  0.31 p0 at depth 0.48 a), and for the solid model also the largest plane-strain von
  Mises stress of the flesh triangles; the fruit is crushed once it exceeds
  ``fruit.failure_stress``, or once its compression exceeds ``fruit.failure_strain``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from gripper_sim.core.deferred import build_deferred
from gripper_sim.core.energies.bending import turning_angles

#: Tresca stress below a Hertz contact over its peak pressure (2 x 0.31, fruit-data.md)
TRESCA_OVER_P0 = 0.62
#: the fewest nodes a deformable finger's patch must spread its load over for its width
#: to be measured: the effective count (sum f)^2 / sum f^2 of its node forces f (a node
#: barely inside the barrier's reach counts for nothing)
RESOLVED_NODES = 3.0


@dataclass(frozen=True)
class Contact:
    """One resolved contact patch (see the module docstring).

    Attributes:
        body: group id of the faces (e.g. 0 left jaw, 1 right jaw, 2 table).
        load: N, normal load F.  centre: (2,) m.  radius: m, Hertz contact radius a.
        peak_pressure: Pa, p0.  equivalent_radius: m, Re.  modulus: Pa, E*.
    """

    body: int
    load: float
    centre: np.ndarray
    radius: float
    peak_pressure: float
    equivalent_radius: float
    modulus: float


@dataclass(frozen=True)
class Damage:
    """Damage state after a step (cumulative since the last reset, where it says so).

    Attributes:
        bruised: the peak pressure has exceeded the bruise threshold (cumulative).
        bruised_length: m, length of the outline bruised so far (cumulative).
        bruised_fraction: bruised length over the rest perimeter (cumulative).
        pressure: Pa, peak contact pressure of this step (Hertz estimate).
        peak_pressure: Pa, the largest so far.
        flesh_stress: Pa, largest flesh stress of this step.
        peak_flesh_stress: Pa, the largest so far.
        crushed: flesh stress or compression beyond failure (cumulative).
        node_pressure: (n_surface,) Pa, this step's contact pressure at each surface node.
        contacts: this step's contact patches.
    """

    bruised: bool
    bruised_length: float
    bruised_fraction: float
    pressure: float
    peak_pressure: float
    flesh_stress: float
    peak_flesh_stress: float
    crushed: bool
    node_pressure: np.ndarray
    contacts: tuple = ()

    def as_dict(self) -> dict:
        """The scalar fields, for JSON."""
        return dict(bruised=bool(self.bruised), bruised_length=float(self.bruised_length),
                    bruised_fraction=float(self.bruised_fraction),
                    peak_pressure=float(self.peak_pressure),
                    peak_flesh_stress=float(self.peak_flesh_stress), crushed=bool(self.crushed))


#: the ``Damage`` fields ``DamageTracker.update`` leaves to first read (``core.deferred``)
DEFERRED_DAMAGE = ('contacts',)


def contact_modulus(youngs_modulus: float, poisson_ratio: float,
                    pad_modulus: float | None = None, pad_poisson: float = 0.0) -> float:
    """E* (Pa) of the fruit against a rigid face, or against a pad of E_p, nu_p."""
    compliance = (1 - poisson_ratio ** 2) / youngs_modulus
    if pad_modulus is not None:
        compliance += (1 - pad_poisson ** 2) / pad_modulus
    return 1.0 / compliance


@njit(cache=True, error_model='numpy')
def hertz(load: float, equivalent_radius: float, modulus: float) -> tuple[float, float]:
    """(a, p0): Hertz contact radius (m) and peak pressure (Pa) of a load (N)."""
    if load <= 0:
        return 0.0, 0.0
    a = (3.0 * load * equivalent_radius / (4.0 * modulus)) ** (1.0 / 3.0)
    return a, 3.0 * load / (2.0 * math.pi * a * a)


# ---------------------------------------------------------------------- the rule, compiled
#: columns of the face table of ``damage_patches`` (one row per obstacle index): the id of
#: the body the face belongs to, its in-plane curvature 1/m, 1.0 where a soft pad covers
#: it, 1.0 where it is a deformable finger
FACE_BODY, FACE_CURVATURE, FACE_PADDED, FACE_DEFORMABLE, FACE_SIZE = range(5)
#: columns of the patch table of ``damage_patches`` (one row per contact patch): body id,
#: load N, centre (x, z) m, Hertz radius a m, peak pressure p0 Pa, equivalent radius Re m,
#: contact modulus E* Pa
(P_BODY, P_LOAD, P_CX, P_CZ, P_RADIUS, P_PEAK, P_RE, P_MODULUS, P_SIZE) = range(9)


@njit(cache=True, error_model='numpy')
def damage_patches(x, normal, obstacle, ring, faces, rest_curvature, bruise_pressure,
                   rigid_modulus, pad_modulus, depth, covered, node_pressure, patches, near_out):
    """The per-step rule of the module docstring: the contact patches by Hertz, the
    per-node pressure and the bruised cover.

    Args:
        x: (n, 2) m.  normal: (n,) N, each node's normal reaction (0 if free).
        obstacle: (n,) int64, the obstacle index holding each node, -1 if free.
        ring: (n_s,) int64 outline nodes in order.  faces: (n_faces, FACE_SIZE) the face
        table (FACE_* columns).  rest_curvature: (n_s,) 1/m, of the rest outline.
        bruise_pressure, rigid_modulus, pad_modulus: Pa (E* against a rigid face and
        against what covers the padded faces).  depth: m, out-of-plane depth b.
        covered: (n_s,) m, bruised length per outline position, raised in place.
        node_pressure: (n_s,) Pa, output.  patches: (n_s, P_SIZE) output rows.
        near_out: (n_s,) int64 output, per patch the outline position nearest its centre.

    Returns:
        (number of patches, largest peak pressure Pa, bruised length sum(covered) m).
    """
    n = ring.shape[0]
    node_pressure[:] = 0.0
    body = np.empty(n, np.int64)
    any_held = False
    for r in range(n):
        o = obstacle[ring[r]]
        body[r] = np.int64(faces[o, FACE_BODY]) if o >= 0 else -1
        any_held = any_held or body[r] >= 0
    if not any_held:
        return 0, 0.0, np.sum(covered)
    start = 0  # a position where the body changes (0 if one body holds all), then once around
    for r in range(n):
        if body[r] != body[(r - 1) % n]:
            start = r
            break
    seg = np.empty(n)  # m, outline position r -> r + 1
    for r in range(n):
        i, j = ring[r], ring[(r + 1) % n]
        seg[r] = math.sqrt((x[j, 0] - x[i, 0]) ** 2 + (x[j, 1] - x[i, 1]) ** 2)
    run = np.empty(n, np.int64)
    n_patches = 0
    k = 0
    while k < n:
        b = body[(start + k) % n]
        length = 0
        while k < n and body[(start + k) % n] == b:
            run[length] = (start + k) % n
            length += 1
            k += 1
        if b < 0:
            continue
        load = cx = cz = 0.0
        for m in range(length):
            node = ring[run[m]]
            f = max(normal[node], 0.0)
            load += f
            cx += f * x[node, 0]
            cz += f * x[node, 1]
        if load <= 0:
            continue
        cx /= load
        cz /= load
        near = run[0]
        best = np.inf
        face_k = padded = deformable = 0.0
        square_sum = 0.0  # N^2, of the node forces
        arc = arc_mean = 0.0  # m, along the outline from the run's first node
        for m in range(length):
            r = run[m]
            node = ring[r]
            dist = math.sqrt((x[node, 0] - cx) ** 2 + (x[node, 1] - cz) ** 2)
            if dist < best:
                best = dist
                near = r
            o = obstacle[node]
            face_k += faces[o, FACE_CURVATURE]
            padded += faces[o, FACE_PADDED]
            deformable += faces[o, FACE_DEFORMABLE]
            if m:
                arc += seg[run[m - 1]]
            f = max(normal[node], 0.0)
            square_sum += f * f
            arc_mean += f * arc / load
        k1 = rest_curvature[near]
        if k1 <= 0:
            k1 = 1e-3  # a flat or concave piece of outline: a 1 km radius
        modulus = pad_modulus if padded / length >= 0.5 else rigid_modulus
        if deformable / length >= 0.5 and load * load >= RESOLVED_NODES * square_sum:
            # R1' = pi E* sigma^2 / F' from the patch's width (module docstring)
            arc = variance = 0.0
            for m in range(length):
                if m:
                    arc += seg[run[m - 1]]
                variance += max(normal[ring[run[m]]], 0.0) * (arc - arc_mean) ** 2 / load
            k1_eff = load / depth / (math.pi * modulus * variance)
        else:  # (a deformable finger's unresolved patch too: its faces are flat) a face
            # more curved than the fruit conforms to it: 1/1000 of its curvature
            k1_eff = max(k1 + face_k / length, 1e-3 * k1)
        re = 1.0 / math.sqrt(k1_eff * k1)
        a, p0 = hertz(load, re, modulus)
        row = patches[n_patches]
        row[P_BODY], row[P_LOAD], row[P_CX], row[P_CZ] = b, load, cx, cz
        row[P_RADIUS], row[P_PEAK], row[P_RE], row[P_MODULUS] = a, p0, re, modulus
        near_out[n_patches] = near
        n_patches += 1
        for m in range(length):
            node = ring[run[m]]
            s = math.sqrt((x[node, 0] - cx) ** 2 + (x[node, 1] - cz) ** 2)
            node_pressure[run[m]] = p0 * math.sqrt(max(0.0, 1.0 - (s / a) ** 2))
        if p0 > bruise_pressure and n >= 3:
            _cover(x, ring, near, cx, cz, seg,
                   a * math.sqrt(1.0 - (bruise_pressure / p0) ** 2), covered)
    pressure = 0.0
    for m in range(n_patches):
        pressure = max(pressure, patches[m, P_PEAK])
    return n_patches, pressure, np.sum(covered)


@njit(cache=True, error_model='numpy')
def _cover(x, ring, near, cx, cz, seg, radius, covered):
    """Raise ``covered`` (n_s,) m to the length of each outline position's share (half
    the segments on either side) lying within ``radius`` (m, along the outline) of the
    centre (cx, cz) m, measured from the position ``near`` along the outline's tangent
    there. ``seg`` (n_s,) m: outline position r -> r + 1."""
    n = ring.shape[0]
    rel = np.zeros(n)  # m, each position's distance along the outline from ``near``
    ahead = n // 2
    acc = 0.0
    for k in range(ahead):
        acc += seg[(near + k) % n]
        rel[(near + 1 + k) % n] = acc
    acc = 0.0
    for k in range(n - 1 - ahead):
        r = (near - 1 - k) % n
        acc += seg[r]
        rel[r] = -acc
    i0, i1, i2 = ring[(near - 1) % n], ring[near], ring[(near + 1) % n]
    tx, tz = x[i2, 0] - x[i0, 0], x[i2, 1] - x[i0, 1]
    norm = max(math.sqrt(tx * tx + tz * tz), 1e-300)
    tx, tz = tx / norm, tz / norm
    offset = (cx - x[i1, 0]) * tx + (cz - x[i1, 1]) * tz
    for r in range(n):
        lo = rel[r] - 0.5 * seg[(r - 1) % n]
        hi = rel[r] + 0.5 * seg[r]
        cover = max(min(hi, offset + radius) - max(lo, offset - radius), 0.0)
        covered[r] = max(covered[r], cover)


# ---------------------------------------------------------------------- the tracker
class DamageTracker:
    """Accumulates damage step by step.

    Args:
        fruit: the FruitModel.  config: the flat configuration.
        face_groups: per obstacle index, the id of the body it belongs to (faces of
            one jaw share an id).
        face_curvature: per obstacle index, its in-plane curvature (1/m, negative for
            a concave face; 0 flat).
        face_padded: per obstacle index, whether a soft pad covers it.
        pad_material: (E Pa, nu) of what covers the padded faces (a deformable finger);
            None: the soft pad's (``gripper.finger.pad.*``).
        face_deformable: per obstacle index, whether it is a deformable finger, whose
            in-plane radius is measured from the patch's width (module docstring); None: none is.
    """

    def __init__(self, fruit, config, face_groups, face_curvature, face_padded,
                 pad_material: tuple[float, float] | None = None,
                 face_deformable: list[bool] | None = None):
        self.fruit = fruit
        self.bruise_pressure = float(config['fruit.bruise_pressure'])
        self.failure_stress = float(config['fruit.failure_stress'])
        self.failure_strain = config.get('fruit.failure_strain')
        e, nu = config['fruit.flesh.youngs_modulus'], config['fruit.flesh.poisson_ratio']
        self.rigid_modulus = contact_modulus(e, nu)
        if pad_material is None:
            pad_material = (config['gripper.finger.pad.youngs_modulus'],
                            config['gripper.finger.pad.poisson_ratio'])
        self.pad_modulus = contact_modulus(e, nu, *pad_material)
        self.groups = list(face_groups)
        self.curvature = list(face_curvature)
        self.padded = list(face_padded)
        self.deformable = (list(face_deformable) if face_deformable is not None
                           else [False] * len(self.padded))
        #: (n_faces, FACE_SIZE) the face table of ``damage_patches``
        self.faces = np.zeros((len(self.groups), FACE_SIZE))
        self.faces[:, FACE_BODY] = self.groups
        self.faces[:, FACE_CURVATURE] = self.curvature
        self.faces[:, FACE_PADDED] = self.padded
        self.faces[:, FACE_DEFORMABLE] = self.deformable
        self.depth = float(fruit.depth)
        ring = np.ascontiguousarray(fruit.surface, dtype=np.int64)
        self.ring = ring
        rest = fruit.rest_positions
        if len(ring) >= 3:
            triples = np.stack([np.roll(ring, 1), ring, np.roll(ring, -1)], axis=1)
            phi = turning_angles(rest, triples)
            seg = np.linalg.norm(rest[np.roll(ring, -1)] - rest[ring], axis=1)
            voronoi = 0.5 * (seg + np.roll(seg, 1))
            self.rest_curvature = np.maximum(phi / voronoi, 0.0)
            self.perimeter = float(seg.sum())
        else:
            self.rest_curvature = np.zeros(len(ring))
            self.perimeter = 0.0
        self.reset()

    def reset(self) -> None:
        n = len(self.ring)
        self.covered = np.zeros(n)
        self.peak_pressure = 0.0
        self.peak_flesh_stress = 0.0
        self.crushed = False

    def _patches(self, positions: np.ndarray, normal_force: np.ndarray, obstacle: np.ndarray,
                 covered: np.ndarray):
        """``damage_patches`` raising ``covered``: (a callable giving the contacts (tuple,
        made on call), the outline position nearest each one's centre (k,), node pressure
        (n_surface,) Pa, largest peak pressure Pa, bruised length m)."""
        n = len(self.ring)
        node_pressure = np.empty(n)
        table = np.empty((n, P_SIZE))
        near = np.empty(n, np.int64)
        count, pressure, length = damage_patches(
            np.ascontiguousarray(positions, dtype=float),
            np.ascontiguousarray(normal_force, dtype=float),
            np.ascontiguousarray(obstacle, dtype=np.int64), self.ring, self.faces,
            self.rest_curvature, self.bruise_pressure, self.rigid_modulus, self.pad_modulus,
            self.depth, covered, node_pressure, table, near)
        rows = table[:count]

        def contacts() -> tuple:
            return tuple(Contact(int(b), load, np.array([cx, cz]), a, p0, re, modulus)
                         for b, load, cx, cz, a, p0, re, modulus in rows.tolist())
        return contacts, near[:count], node_pressure, pressure, length

    def contacts(self, positions: np.ndarray, normal_force: np.ndarray,
                 obstacle: np.ndarray) -> list[tuple[Contact, int]]:
        """The contact patches, each with the outline position nearest its centre; the
        tracker's state stays as it is.

        Args:
            positions: (n_nodes, 2) m.  normal_force: (n_nodes,) N, each node's normal
            reaction (0 if free).  obstacle: (n_nodes,) the obstacle index holding each
            node, -1 if free.
        """
        contacts, near, *_ = self._patches(positions, normal_force, obstacle,
                                           self.covered.copy())
        return list(zip(contacts(), near.tolist()))

    def record(self, covered: np.ndarray, pressure: float, flesh_stress: float,
               compression_ratio: float) -> float:
        """Take a step's damage measures into the run's: the outline's cover after it
        (n_surface,) (kept), its largest contact peak pressure (Pa) and resolved flesh
        stress (Pa), its compression ratio; the peaks rise and the fruit is crushed past
        the failure stress or strain. Returns the step's flesh stress (Pa): the larger of
        the contact's Tresca stress and ``flesh_stress``."""
        self.covered = covered
        stress = max(TRESCA_OVER_P0 * pressure, float(flesh_stress))
        self.peak_pressure = max(self.peak_pressure, pressure)
        self.peak_flesh_stress = max(self.peak_flesh_stress, stress)
        if self.peak_flesh_stress > self.failure_stress:
            self.crushed = True
        if self.failure_strain is not None and compression_ratio > self.failure_strain:
            self.crushed = True
        return stress

    def take_run(self, covered: np.ndarray, peak_pressure: float, peak_flesh_stress: float,
                 crushed: bool) -> None:
        """Take the state a run of steps computed elsewhere left (``core.multistep``):
        the outline's cover (n_surface,), the peak pressure and flesh stress (Pa) and
        whether the fruit is crushed."""
        self.covered = covered
        self.peak_pressure = peak_pressure
        self.peak_flesh_stress = peak_flesh_stress
        self.crushed = crushed

    def update(self, positions: np.ndarray, normal_force: np.ndarray, obstacle: np.ndarray,
               compression_ratio: float, flesh_stress: float = 0.0) -> Damage:
        """Damage after a step (its ``contacts`` made on first read).

        Args:
            positions: (n_nodes, 2) m.  normal_force: (n_nodes,) N.  obstacle:
            (n_nodes,) int.  compression_ratio: width loss over the rest width.
            flesh_stress: Pa, a resolved flesh stress (the solid's von Mises), 0 if none.
        """
        contacts, _, node_pressure, pressure, length = self._patches(
            positions, normal_force, obstacle, self.covered)
        stress = self.record(self.covered, pressure, flesh_stress, compression_ratio)
        return build_deferred(
            Damage, dict(bruised=self.peak_pressure > self.bruise_pressure,
                         bruised_length=length,
                         bruised_fraction=length / self.perimeter if self.perimeter > 0 else 0.0,
                         pressure=pressure, peak_pressure=self.peak_pressure,
                         flesh_stress=stress, peak_flesh_stress=self.peak_flesh_stress,
                         crushed=self.crushed, node_pressure=node_pressure),
            DEFERRED_DAMAGE, lambda: dict(contacts=contacts()))
