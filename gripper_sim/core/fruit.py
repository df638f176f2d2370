"""The fruit model built from configuration: nodes, masses, skin and energies.

Skin constants from the configuration (E_s skin modulus, t skin thickness, b depth):
    EA = E_s t b    (N)         axial stiffness of the skin ring
    EI = E_s t^3 b / 12 (N m^2) bending stiffness of the skin ring
Flesh: the shell model stands in for it with an enclosed-area pressure, the solid
model with neo-Hookean triangles (E, nu of the flesh).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core.energies import (EnclosedAreaPressure, Energy, NeoHookeanTriangles,
                                       RingBending, Stretching)
from gripper_sim.core.mesh import mesh_outline
from gripper_sim.geometry import shapes


@dataclass(frozen=True)
class FruitModel:
    """Attributes:
        rest_positions: (n_nodes, 2) m, rest shape centred at the origin.
        masses: (n_nodes,) kg, lumped.
        surface: (n_surface,) node indices of the outline, counter-clockwise.
        skin_edges: (n_surface, 2) node indices of outline segments.
        energies: internal (elastic) energies.
        stretching: the skin stretching energy (for strain output), or None.
        pressure: the enclosed-area pressure (shell model), or None.
        flesh: the neo-Hookean flesh (solid model), or None.
        triangles: (n_tri, 3) flesh triangles (empty for the shell model).
        depth: m, out-of-plane depth.
        rest_width: m, extent of the rest shape along x.
        axial_stiffness, bending_stiffness: EA (N) and EI (N m^2) of the skin.
    """

    rest_positions: np.ndarray
    masses: np.ndarray
    surface: np.ndarray
    skin_edges: np.ndarray
    energies: tuple
    stretching: Stretching | None
    pressure: EnclosedAreaPressure | None
    flesh: NeoHookeanTriangles | None
    triangles: np.ndarray
    depth: float
    rest_width: float
    axial_stiffness: float
    bending_stiffness: float

    @property
    def n_nodes(self) -> int:
        return len(self.masses)

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())


def fruit_depth(config, outline: np.ndarray | None = None) -> float:
    """Out-of-plane depth b (m): configured, or 2/3 of the diameter (sphere mass).

    For shapes other than the circle the diameter is that of the circle of the same
    area (``shapes.equivalent_diameter``).
    """
    if config['fruit.depth'] is not None:
        return float(config['fruit.depth'])
    if config.get('fruit.shape.type', 'circle') == 'circle':
        return 2.0 * config['fruit.shape.diameter'] / 3.0
    if outline is None:
        outline = shapes.outline_from_config(config)
    return 2.0 * shapes.equivalent_diameter(config, outline) / 3.0


def bulk_modulus(config) -> float:
    """Area bulk modulus K (Pa) of the shell model's pressure law."""
    if config['fruit.pressure.bulk_modulus'] is not None:
        return float(config['fruit.pressure.bulk_modulus'])
    e, nu = config['fruit.flesh.youngs_modulus'], config['fruit.flesh.poisson_ratio']
    return e / (2 * (1 + nu) * (1 - 2 * nu))


def build_fruit(config) -> FruitModel:
    """Build the fruit model that ``config`` (flat, validated) describes."""
    outline = shapes.outline_from_config(config)
    depth = fruit_depth(config, outline)
    rho = config['fruit.density']
    e_skin, t_skin = config['fruit.skin.youngs_modulus'], config['fruit.skin.thickness']
    ea = e_skin * t_skin * depth
    ei = e_skin * t_skin ** 3 * depth / 12.0
    n_surface = len(outline)
    surface = np.arange(n_surface)
    skin_edges = np.stack([surface, np.roll(surface, -1)], axis=1)
    rest_area = shapes.polygon_area(outline)
    energies: list[Energy] = []
    pressure = flesh = None
    turgor = config['fruit.pressure.turgor'] if config['fruit.model'] == 'shell' else 0.0
    if config['fruit.model'] == 'point':
        mass = rho * rest_area * depth
        return FruitModel(
            rest_positions=np.zeros((1, 2)), masses=np.array([mass]),
            surface=np.zeros(1, np.int64), skin_edges=np.zeros((0, 2), np.int64),
            energies=(), stretching=None, pressure=None, flesh=None,
            triangles=np.zeros((0, 3), np.int64), depth=depth, rest_width=0.0,
            axial_stiffness=0.0, bending_stiffness=0.0)
    if config['fruit.model'] == 'shell':
        positions = outline
        triangles = np.zeros((0, 3), dtype=np.int64)
        seg = np.linalg.norm(outline[skin_edges[:, 1]] - outline[skin_edges[:, 0]], axis=1)
        share = 0.5 * (seg + np.roll(seg, 1))
        masses = rho * rest_area * depth * share / share.sum()
        with_skin = True
        k = bulk_modulus(config)
        if k > 0 or turgor > 0:
            pressure = EnclosedAreaPressure(surface, rest_area, depth, turgor, k)
            energies.append(pressure)
    else:
        positions, triangles = mesh_outline(outline, config['fruit.flesh.mesh_grading'])
        flesh = NeoHookeanTriangles(triangles, positions, config['fruit.flesh.youngs_modulus'],
                                    config['fruit.flesh.poisson_ratio'], depth)
        energies.append(flesh)
        masses = np.zeros(len(positions))
        np.add.at(masses, triangles.ravel(), np.repeat(rho * flesh.volume / 3.0, 3))
        with_skin = config['fruit.skin.enabled']
    stretching = None
    if with_skin:
        rest_lengths = np.linalg.norm(positions[skin_edges[:, 1]] - positions[skin_edges[:, 0]],
                                      axis=1)
        if pressure is not None and turgor > 0:
            # prestress: the skin carries the hoop tension p0 b R of the turgor at the
            # configured shape, so that shape is the equilibrium (R from the perimeter)
            radius = rest_lengths.sum() / (2 * np.pi)
            rest_lengths = rest_lengths / (1.0 + turgor * depth * radius / ea)
        stretching = Stretching(skin_edges, rest_lengths, ea)
        energies = [stretching, RingBending(surface, positions, ei)] + energies
    return FruitModel(
        rest_positions=positions, masses=masses, surface=surface, skin_edges=skin_edges,
        energies=tuple(energies), stretching=stretching, pressure=pressure, flesh=flesh,
        triangles=triangles, depth=depth,
        rest_width=float(np.ptp(outline[:, 0])), axial_stiffness=ea, bending_stiffness=ei)
