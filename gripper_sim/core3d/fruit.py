"""The 3D fruit model built from configuration: nodes, masses, skin and energies.

Skin constants (E_s skin modulus, t thickness, nu_s ``fruit.skin.poisson_ratio``):
membrane E_s t (SVK, plane stress), plate bending D = E_s t^3 / (12 (1 - nu_s^2)).
Flesh: the shell model stands in for it with an enclosed-volume pressure (turgor p0,
bulk modulus K), the solid model with neo-Hookean tetrahedra (E, nu of the flesh).

With turgor the skin is prestressed so that the configured shape is (close to) the
equilibrium: a sphere of radius R under p0 carries the membrane tension p0 R / 2, which
equibiaxial SVK gives at the stretch lambda^2 = 1 + p0 R (1 - nu_s) / (E_s t), so the
stress-free skin is the configured one shrunk by 1 / lambda (R: the radius of the
sphere of equal volume, exact for spheres, approximate otherwise). On a discrete,
non-uniform mesh (and for other shapes) the discrete tension and pressure forces do not
balance exactly at the configured shape, so the shell is then relaxed to its free
equilibrium (form finding: quasi-static implicit Euler steps, no contact, no gravity),
which becomes the rest shape the simulation starts from.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core.energies.base import Energy
from gripper_sim.core.fast_solver import PatternCachingSolver
from gripper_sim.core.stepper import NewtonFailure, StepConstraints
from gripper_sim.core3d import meshes
from gripper_sim.core3d.energies import (EnclosedVolumePressure, HingeBending, Membrane,
                                         NeoHookeanTets, quadratic_tets)
from gripper_sim.core3d.energies.quadratic_tets import QuadraticNeoHookeanTets
from gripper_sim.core3d.energies.wrinkling_membrane import WrinklingMembrane
from gripper_sim.errors import ConfigError
from gripper_sim.geometry import shapes


@dataclass(frozen=True)
class FruitModel3D:
    """Attributes:
        rest_positions: (n_nodes, 3) m, the configured shape centred at the origin.
        masses: (n_nodes,) kg, lumped.
        surface: (n_surface,) node indices of the skin (surface) vertices.
        triangles: (n_tri, 3) outward skin triangles (node indices).
        tetrahedra: (n_tet, 4) flesh tetrahedra (empty for the shell model), or
            (n_tet, 10) quadratic ones (``fruit.mesh.order`` 2).
        skin_edges: (n_edge, 2) unique surface edges.
        energies: internal (elastic) energies.
        membrane, bending: the skin energies (membrane: ``Membrane`` or, with
            ``fruit.skin.wrinkling``, ``WrinklingMembrane``), or None.
        pressure: the enclosed-volume pressure (shell model), or None.
        flesh: the neo-Hookean tetrahedra, linear or quadratic (solid model), or None.
        rest_width: m, extent of the rest shape along x.
        rest_volume: m^3, volume the skin encloses at rest.
        bending_stiffness: D of the skin, N m.
    """

    rest_positions: np.ndarray
    masses: np.ndarray
    surface: np.ndarray
    triangles: np.ndarray
    tetrahedra: np.ndarray
    skin_edges: np.ndarray
    energies: tuple
    membrane: Membrane | WrinklingMembrane | None
    bending: HingeBending | None
    pressure: EnclosedVolumePressure | None
    flesh: NeoHookeanTets | None
    rest_width: float
    rest_volume: float
    bending_stiffness: float

    dimension = 3

    @property
    def n_nodes(self) -> int:
        return len(self.masses)

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())


def bulk_modulus_3d(config) -> float:
    """Bulk modulus K (Pa) of the shell model's pressure law."""
    if config['fruit.pressure.bulk_modulus'] is not None:
        return float(config['fruit.pressure.bulk_modulus'])
    e, nu = config['fruit.flesh.youngs_modulus'], config['fruit.flesh.poisson_ratio']
    return e / (3 * (1 - 2 * nu))


def body_from_config(config) -> meshes.SurfaceMesh:
    """The surface mesh (centred at the origin) of the configured body.

    The 2D outline revolved about z (``fruit.shape.*``; the circle exactly, as a
    sphere), then rotated by ``fruit.shape.angle`` about y and stretched along y to
    ``fruit.shape.width`` when that is set.
    """
    frequency = int(config['fruit.mesh.subdivisions'])
    refinement = float(config['fruit.mesh.jaw_refinement'])
    kind = config['fruit.shape.type']
    diameter = float(config['fruit.shape.diameter'])
    if kind == 'circle':
        body = meshes.body_surface('sphere', frequency, refinement, radius=0.5 * diameter)
    elif kind == 'ellipse':
        height = config.get('fruit.shape.height') or diameter
        body = meshes.body_surface('ellipsoid', frequency, refinement, radius=0.5 * diameter,
                                   semi_axes=(0.5 * diameter, 0.5 * diameter, 0.5 * height))
    else:
        unrotated = dict(config)
        unrotated['fruit.shape.angle'] = 0.0
        outline = shapes.outline_from_config(unrotated)
        body = meshes.body_surface('revolution', frequency, refinement,
                                   radius=0.5 * diameter, profile=_meridian(outline))
    x = body.positions.copy()
    angle = np.radians(float(config.get('fruit.shape.angle', 0.0) or 0.0))
    if angle != 0.0:
        c, s = np.cos(angle), np.sin(angle)
        x[:, 0], x[:, 2] = c * x[:, 0] - s * x[:, 2], s * x[:, 0] + c * x[:, 2]
    width = config.get('fruit.shape.width')
    if width is not None:
        x[:, 1] *= float(width) / float(np.ptp(x[:, 1]))
    x -= 0.5 * (x.max(axis=0) + x.min(axis=0))
    return meshes.SurfaceMesh(x, body.triangles)


def _meridian(outline: np.ndarray) -> np.ndarray:
    """(k, 2) (r, z) profile from the right half (x >= axis) of a closed 2D outline.

    The axis is the vertical through the outline's area centroid; the half is cut where
    the outline crosses the axis (top and bottom).
    """
    centre = shapes.polygon_centroid(outline)
    p = outline - centre
    n = len(p)
    right = p[:, 0] >= 0
    # walk counter-clockwise from the bottom crossing to the top crossing on the right
    crossings = [i for i in range(n) if (p[i, 0] < 0) != (p[(i + 1) % n, 0] < 0)]
    if len(crossings) != 2:
        raise ConfigError("config key 'fruit.shape.type': the 3D model revolves the outline "
                          'about its vertical axis, which must cross it exactly twice')
    pts = []
    for i in crossings:
        a, b = p[i], p[(i + 1) % n]
        t = a[0] / (a[0] - b[0])
        pts.append((i, np.array([0.0, a[1] + t * (b[1] - a[1])])))
    (i0, c0), (i1, c1) = pts
    if c0[1] > c1[1]:
        (i0, c0), (i1, c1) = (i1, c1), (i0, c0)
    idx = [(i0 + 1 + k) % n for k in range(n)]
    inner = []
    for j in idx:
        if not right[j]:
            break
        inner.append(p[j])
    profile = np.vstack([c0[None], np.array(inner).reshape(-1, 2), c1[None]])
    profile[:, 1] += centre[1]
    return profile


def _relax(positions: np.ndarray, masses: np.ndarray, energies, steps: int = 40):
    """The free equilibrium (n, 3) of the shell near ``positions``, centred as given.

    Raises:
        ConfigError: no equilibrium found (e.g. a skin too soft for its turgor).
    """
    solver = PatternCachingSolver(masses, list(energies), damping_mass=100.0, tolerance=1e-9,
                                  max_iterations=30, dim=3)
    q = positions.ravel().copy()
    size = float(np.ptp(positions))
    free = StepConstraints.free(len(masses), dim=3)
    dt = 0.05
    for _ in range(steps):
        try:
            q_new = solver.solve(q, np.zeros_like(q), dt, q, free).q
        except NewtonFailure as err:
            raise ConfigError("config keys 'fruit.pressure.turgor' / 'fruit.skin.*': the "
                              f'pressurised skin has no equilibrium near its shape ({err})'
                              ) from err
        moved = float(np.max(np.abs(q_new - q)))
        q = q_new
        if moved < 1e-7 * size:
            break
    x = q.reshape(-1, 3)
    return x - (masses @ x) / masses.sum() + (masses @ positions) / masses.sum()


def build_fruit3d(config) -> FruitModel3D:
    """Build the 3D fruit model that ``config`` (flat, validated) describes.

    Raises:
        ConfigError: a model the 3D path does not have (point), TetGen missing.
    """
    model = config['fruit.model']
    if model not in ('shell', 'solid'):
        raise ConfigError(f"config key 'fruit.model': the 3D model has shell and solid "
                          f"fruits, not '{model}' (use dimension: 2 for it)")
    body = body_from_config(config)
    rho = config['fruit.density']
    e_s, t_s = config['fruit.skin.youngs_modulus'], config['fruit.skin.thickness']
    nu_s = config['fruit.skin.poisson_ratio']
    d_s = e_s * t_s ** 3 / (12 * (1 - nu_s ** 2))
    rest_volume = meshes.enclosed_volume(body.positions, body.triangles)
    energies: list[Energy] = []
    pressure = flesh = None
    tets = np.zeros((0, 4), np.int64)
    surface, triangles = np.arange(len(body.positions)), body.triangles
    if model == 'shell':
        positions = body.positions
        n = len(positions)
        areas = meshes.vertex_areas(positions, body.triangles, n)
        masses = rho * rest_volume * areas / areas.sum()
        turgor = config['fruit.pressure.turgor']
        k = bulk_modulus_3d(config)
        if k > 0 or turgor > 0:
            pressure = EnclosedVolumePressure(body.triangles, rest_volume, turgor, k)
            energies.append(pressure)
        with_skin = True
    else:
        order = int(config.get('fruit.mesh.order', 1))
        volume_mesh = meshes.tetrahedralize(body, config['fruit.mesh.max_tet_volume'],
                                            order=order)
        positions, tets = volume_mesh.positions, volume_mesh.tetrahedra
        surface, triangles = volume_mesh.surface_nodes, volume_mesh.triangles
        e_f, nu_f = config['fruit.flesh.youngs_modulus'], config['fruit.flesh.poisson_ratio']
        if order == 2:
            flesh = QuadraticNeoHookeanTets(tets, positions, e_f, nu_f)
            masses = quadratic_tets.lumped_masses(tets, flesh.volume, rho, len(positions))
        else:
            flesh = NeoHookeanTets(tets, positions, e_f, nu_f)
            masses = np.bincount(tets.ravel(), weights=np.repeat(rho * flesh.volume / 4.0, 4),
                                 minlength=len(positions))
        energies.append(flesh)
        turgor = 0.0
        with_skin = bool(config['fruit.skin.enabled'])
    membrane = bending = None
    if with_skin:
        skin_rest = positions
        if turgor > 0:
            radius = (3 * rest_volume / (4 * np.pi)) ** (1 / 3)
            stretch = np.sqrt(1 + turgor * radius * (1 - nu_s) / (e_s * t_s))
            skin_rest = positions / stretch
        skin_energy = WrinklingMembrane if config['fruit.skin.wrinkling'] else Membrane
        membrane = skin_energy(triangles, skin_rest, e_s, nu_s, t_s)
        bending = HingeBending(meshes.hinges(triangles), positions, d_s)
        energies = [membrane, bending] + energies
    if model == 'shell' and pressure is not None:
        positions = _relax(positions, masses, energies)
        pressure.v0 = meshes.enclosed_volume(positions, body.triangles)
        rest_volume = pressure.v0
    return FruitModel3D(
        rest_positions=positions, masses=masses, surface=surface,
        triangles=triangles, tetrahedra=tets,
        skin_edges=meshes.surface_edges(triangles), energies=tuple(energies),
        membrane=membrane, bending=bending, pressure=pressure, flesh=flesh,
        rest_width=float(np.ptp(positions[:, 0])), rest_volume=rest_volume,
        bending_stiffness=d_s)
