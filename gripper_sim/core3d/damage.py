"""Damage of the 3D fruit: bruising from the resolved contact pressure, crushing.

Unlike the planar model (which estimates a round patch by Hertz, ``core.damage``), the
3D model resolves the contact patch: the pressure at a surface node is its normal
reaction over its vertex area (a third of each adjacent triangle).

- a node is bruised once its pressure exceeds ``fruit.bruise_pressure`` (a bruise
  stays); the bruised area is the rest vertex area of the bruised nodes, its fraction
  over the rest surface area, and ``bruised_length`` (the planar field) reports the
  diameter of the circle of that area, 2 sqrt(A / pi);
- flesh stress: for the solid model the largest von Mises stress of the tetrahedra,
  for the shell the Tresca estimate 0.62 p below the most loaded node (fruit-data.md,
  tau_max = 0.31 p0 at depth 0.48 a); the fruit is crushed once it exceeds
  ``fruit.failure_stress`` or its compression exceeds ``fruit.failure_strain``.
"""
from __future__ import annotations

import math

import numpy as np

from gripper_sim.core.damage import TRESCA_OVER_P0, Damage
from gripper_sim.core3d import meshes


class DamageTracker3D:
    """Cumulative damage of one run (reset with the simulation).

    Args:
        fruit: the FruitModel3D.  config: flat configuration.
    """

    def __init__(self, fruit, config):
        self.fruit = fruit
        self.bruise_pressure = float(config['fruit.bruise_pressure'])
        self.failure_stress = float(config['fruit.failure_stress'])
        self.failure_strain = config.get('fruit.failure_strain')
        self.rest_areas = meshes.vertex_areas(fruit.rest_positions, fruit.triangles,
                                              fruit.n_nodes)[fruit.surface]
        self.total_area = float(self.rest_areas.sum())
        self.bruised_nodes = np.zeros(len(fruit.surface), bool)
        self.peak_pressure = 0.0
        self.peak_flesh_stress = 0.0
        self.crushed = False

    def update(self, positions: np.ndarray, node_pressure: np.ndarray,
               compression_ratio: float) -> Damage:
        """Damage after a step with node pressures (n_surface,) Pa."""
        pressure = float(node_pressure.max(initial=0.0))
        self.peak_pressure = max(self.peak_pressure, pressure)
        self.bruised_nodes |= node_pressure > self.bruise_pressure
        if self.fruit.flesh is not None:
            stress = float(self.fruit.flesh.von_mises(positions.ravel()).max(initial=0.0))
        else:
            stress = TRESCA_OVER_P0 * pressure
        self.peak_flesh_stress = max(self.peak_flesh_stress, stress)
        if self.peak_flesh_stress > self.failure_stress:
            self.crushed = True
        if self.failure_strain is not None and compression_ratio > self.failure_strain:
            self.crushed = True
        area = float(self.rest_areas[self.bruised_nodes].sum())
        return Damage(bruised=bool(self.bruised_nodes.any()),
                      bruised_length=2 * math.sqrt(area / math.pi),
                      bruised_fraction=area / self.total_area if self.total_area > 0 else 0.0,
                      pressure=pressure, peak_pressure=self.peak_pressure,
                      flesh_stress=stress, peak_flesh_stress=self.peak_flesh_stress,
                      crushed=self.crushed, node_pressure=node_pressure)
