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
  shows it as the patch's peak line pressure p_l (the largest node force over its
  tributary length and b, as ``Deformation.peak_contact_pressure``). R1' is the radius
  with which plane-strain Hertz has that peak at the patch's line load F' = F / b:
  p_l = sqrt(F' E* / (pi R1')) (Johnson 1985, eqs. 4.43-4.44), R1' = F' E* / (pi p_l^2).
  For two elastic half-planes that is the fruit's R1 again; a finger that wraps spreads
  the load, so R1' grows and p0 falls; a finger that presses harder at a rib raises p_l
  there and p0 with it;
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

from gripper_sim.core.energies.bending import turning_angles

#: Tresca stress below a Hertz contact over its peak pressure (2 x 0.31, fruit-data.md)
TRESCA_OVER_P0 = 0.62


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


def contact_modulus(youngs_modulus: float, poisson_ratio: float,
                    pad_modulus: float | None = None, pad_poisson: float = 0.0) -> float:
    """E* (Pa) of the fruit against a rigid face, or against a pad of E_p, nu_p."""
    compliance = (1 - poisson_ratio ** 2) / youngs_modulus
    if pad_modulus is not None:
        compliance += (1 - pad_poisson ** 2) / pad_modulus
    return 1.0 / compliance


def hertz(load: float, equivalent_radius: float, modulus: float) -> tuple[float, float]:
    """(a, p0): Hertz contact radius (m) and peak pressure (Pa) of a load (N)."""
    if load <= 0:
        return 0.0, 0.0
    a = (3.0 * load * equivalent_radius / (4.0 * modulus)) ** (1.0 / 3.0)
    return a, 3.0 * load / (2.0 * math.pi * a * a)


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
            in-plane radius is measured from the patch's peak line pressure (module
            docstring); None: none is.
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
        self.depth = float(fruit.depth)
        ring = np.asarray(fruit.surface)
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

    # ------------------------------------------------------------------ contacts
    def _runs(self, obstacle_of_surface: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """Runs of consecutive surface positions held by one body: (body, positions)."""
        n = len(obstacle_of_surface)
        body = np.array([self.groups[o] if o >= 0 else -1 for o in obstacle_of_surface])
        if not np.any(body >= 0):
            return []
        if np.all(body == body[0]):
            return [(int(body[0]), np.arange(n))]
        # start at a position where the body changes, then walk once around
        start = int(np.flatnonzero(body != np.roll(body, 1))[0])
        runs, current, positions = [], None, []
        for k in range(n):
            i = (start + k) % n
            if body[i] != current:
                if current is not None and current >= 0:
                    runs.append((current, np.array(positions)))
                current, positions = body[i], []
            positions.append(i)
        if current is not None and current >= 0:
            runs.append((current, np.array(positions)))
        return runs

    def contacts(self, positions: np.ndarray, normal_force: np.ndarray,
                 obstacle: np.ndarray) -> list[tuple[Contact, np.ndarray, int]]:
        """The contact patches: (Contact, surface positions of its nodes, the position
        nearest its centre).

        Args:
            positions: (n_nodes, 2) m.  normal_force: (n_nodes,) N, each node's normal
            reaction (0 if free).  obstacle: (n_nodes,) the obstacle index holding each
            node, -1 if free.
        """
        ring = self.ring
        out = []
        tributary = None
        for body, run in self._runs(obstacle[ring]):
            nodes = ring[run]
            f = np.maximum(normal_force[nodes], 0.0)
            load = float(f.sum())
            if load <= 0:
                continue
            centre = (f @ positions[nodes]) / load
            near = run[int(np.argmin(np.linalg.norm(positions[nodes] - centre, axis=1)))]
            k1 = float(self.rest_curvature[near])
            if k1 <= 0:
                k1 = 1e-3  # a flat or concave piece of outline: a 1 km radius
            faces = obstacle[nodes]
            padded = np.mean([self.padded[o] for o in faces]) >= 0.5
            modulus = self.pad_modulus if padded else self.rigid_modulus
            if np.mean([self.deformable[o] for o in faces]) >= 0.5:
                if tributary is None:  # half the outline segments at each node (m)
                    seg = np.linalg.norm(np.roll(positions[ring], -1, axis=0)
                                         - positions[ring], axis=1)
                    tributary = 0.5 * (seg + np.roll(seg, 1))
                line_peak = float(np.max(f / tributary[run])) / self.depth
                k1_eff = math.pi * line_peak ** 2 / (load / self.depth * modulus)
            else:
                face_k = float(np.mean([self.curvature[o] for o in faces]))
                # a face more curved than the fruit conforms to it: keep 1/1000 of its
                # curvature
                k1_eff = max(k1 + face_k, 1e-3 * k1)
            re = 1.0 / math.sqrt(k1_eff * k1)
            a, p0 = hertz(load, re, modulus)
            out.append((Contact(body, load, centre, a, p0, re, modulus), run, near))
        return out

    # ------------------------------------------------------------------ update
    def update(self, positions: np.ndarray, normal_force: np.ndarray, obstacle: np.ndarray,
               compression_ratio: float, flesh_stress: float = 0.0) -> Damage:
        """Damage after a step.

        Args:
            positions: (n_nodes, 2) m.  normal_force: (n_nodes,) N.  obstacle:
            (n_nodes,) int.  compression_ratio: width loss over the rest width.
            flesh_stress: Pa, a resolved flesh stress (the solid's von Mises), 0 if none.
        """
        ring = self.ring
        n = len(ring)
        node_pressure = np.zeros(n)
        x = positions[ring]
        seg = np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)  # i -> i+1
        patches = []
        for contact, run, near in self.contacts(positions, normal_force, obstacle):
            patches.append(contact)
            a, p0 = contact.radius, contact.peak_pressure
            s = np.linalg.norm(x[run] - contact.centre, axis=1)
            node_pressure[run] = p0 * np.sqrt(np.maximum(0.0, 1.0 - (s / a) ** 2))
            if p0 > self.bruise_pressure and n >= 3:
                self._cover(x, near, contact.centre, seg,
                            a * math.sqrt(1.0 - (self.bruise_pressure / p0) ** 2))
        pressure = max((c.peak_pressure for c in patches), default=0.0)
        stress = max(TRESCA_OVER_P0 * pressure, float(flesh_stress))
        self.peak_pressure = max(self.peak_pressure, pressure)
        self.peak_flesh_stress = max(self.peak_flesh_stress, stress)
        if self.peak_flesh_stress > self.failure_stress:
            self.crushed = True
        if self.failure_strain is not None and compression_ratio > self.failure_strain:
            self.crushed = True
        length = float(self.covered.sum())
        return Damage(bruised=self.peak_pressure > self.bruise_pressure, bruised_length=length,
                      bruised_fraction=length / self.perimeter if self.perimeter > 0 else 0.0,
                      pressure=pressure, peak_pressure=self.peak_pressure,
                      flesh_stress=stress, peak_flesh_stress=self.peak_flesh_stress,
                      crushed=self.crushed, node_pressure=node_pressure,
                      contacts=tuple(patches))

    def _cover(self, x: np.ndarray, near: int, centre: np.ndarray, seg: np.ndarray,
               radius: float) -> None:
        """Mark the outline within ``radius`` (m, along the outline) of ``centre``.

        Args:
            x: (n_surface, 2) m, current outline.  near: surface position nearest the
            centre.  seg: (n_surface,) m, length from each position to the next.
        """
        n = len(x)
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
        cover = np.clip(np.minimum(hi, offset + radius) - np.maximum(lo, offset - radius),
                        0.0, None)
        self.covered = np.maximum(self.covered, cover)
