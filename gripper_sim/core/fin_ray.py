"""The Fin Ray finger as a ``FingerBody`` of discrete elastic rods.

Each member of the layout (``gripper_sim.geometry.fin_ray``) is a chain of rods of
thickness t, depth b and the material's modulus E: axial stiffness EA = E t b and bending
stiffness EI = E t^3 b / 12 (Euler-Bernoulli, rectangular section), bending triples at
the chain's interior nodes. Where members meet (rib on beam, beam on base, the beams at
the tip) the joint is rigid: triples across the joint keep the rest angle between the
members, with the weaker member's EI shared among the triples it takes part in at that
node; with ``rib_joint`` 'pinned' a rib's ends are hinges instead (no triple across
them: the rib carries no moment into the beams). A triple against the base (rigid, on
the jaw) clamps its beam: it stands for half the free edge. The base's nodes are the
body's base nodes; the front beam's edges, tip to base, are its surface (the fruit on
their right-hand side, +x).
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from gripper_sim.core.finger_body import FingerBody
from gripper_sim.errors import ConfigError
from gripper_sim.geometry.fin_ray import (PREFIX, FinRayGeometry, check_geometry,
                                          layout)
from gripper_sim.geometry.finger_materials import MATERIALS, SECTIONS, FingerMaterial


def material_from_config(config) -> FingerMaterial:
    """The ``gripper.finger.fin_ray.material`` (``custom``: the modulus and density keys)."""
    name = config[PREFIX + 'material']
    if name in MATERIALS:
        return MATERIALS[name]
    if name != 'custom':
        raise ConfigError(f"config key '{PREFIX}material': unknown material '{name}'")
    return FingerMaterial(config[PREFIX + 'youngs_modulus'], config[PREFIX + 'density'],
                          'custom', config[PREFIX + 'poisson_ratio'])


def fin_ray_from_config(config, fruit_depth: float, section: str | None = None) -> FingerBody:
    """The Fin Ray finger of a flat configuration (``gripper.finger.fin_ray.*``), as deep
    as the fruit (``fruit_depth``, m) unless ``gripper.finger.fin_ray.depth`` is set; its
    members bend as ``section`` (``fin_ray_body``; None: the configuration's)."""
    return fin_ray_body(FinRayGeometry.from_config(config, fruit_depth),
                        material_from_config(config), section or config[PREFIX + 'section'])


def fin_ray_body(geometry: FinRayGeometry, material: FingerMaterial,
                 section: str = 'beam') -> FingerBody:
    """The finger of ``geometry`` made of ``material``, its members bending as ``section``:
    'beam' (plane stress: E t^3 b / 12 in bending, E t b in stretching) or 'plate' (plane
    strain across the depth b: both divided by 1 - nu^2, nu the material's).

    Raises:
        ConfigError: a geometry that cannot be built (``check_geometry``), or no depth.
        ValueError: a section neither 'beam' nor 'plate'.
    """
    if section not in SECTIONS:
        raise ValueError(f"section {section!r}: must be one of {', '.join(SECTIONS)}")
    if geometry.depth is None:
        raise ConfigError(f"config key '{PREFIX}depth': the finger needs a depth")
    check_geometry(geometry)
    plan = layout(geometry)
    x0 = plan.positions
    b = geometry.depth
    e_mod = material.youngs_modulus
    # the modulus of the members' bending and stretching: plane strain across b for plates
    e_section = e_mod / (1.0 - material.poisson_ratio ** 2) if section == 'plate' else e_mod
    edges, axial, masses = [], [], np.zeros(len(x0))
    triples, stiffness, lengths = [], [], []
    # node -> its arms: (neighbour, member, EI, whether the member ends at the node)
    arms: dict[int, list[tuple[int, int, float, bool]]] = {}
    for k, member in enumerate(plan.members):
        t = member.thickness
        ei = e_section * t ** 3 * b / 12.0
        nodes = member.nodes
        pairs = np.stack([nodes[:-1], nodes[1:]], axis=1)
        edge_lengths = np.linalg.norm(x0[pairs[:, 1]] - x0[pairs[:, 0]], axis=1)
        edges.append(pairs)
        axial.append(np.full(len(pairs), e_section * t * b))
        np.add.at(masses, pairs.ravel(),
                  np.repeat(0.5 * material.density * t * b * edge_lengths, 2))
        for i in range(1, len(nodes) - 1):
            if not member.rigid:
                triples.append((nodes[i - 1], nodes[i], nodes[i + 1]))
                stiffness.append(ei)
                lengths.append(0.5 * (edge_lengths[i - 1] + edge_lengths[i]))
            arms.setdefault(int(nodes[i]), []).extend(
                [(int(nodes[i - 1]), k, ei, False), (int(nodes[i + 1]), k, ei, False)])
        for end, neighbour in ((nodes[0], nodes[1]), (nodes[-1], nodes[-2])):
            arms.setdefault(int(end), []).append((int(neighbour), k, ei, not member.rigid))
    hinged = ({k for k, member in enumerate(plan.members) if member.name.startswith('rib')}
              if geometry.rib_joint == 'pinned' else set())
    for joint, joint_arms in arms.items():
        cross = [(a, c) for a, c in combinations(joint_arms, 2)
                 if a[1] != c[1] and a[1] not in hinged and c[1] not in hinged]
        taken: dict[tuple, int] = {}
        for pair in cross:
            for arm in pair:
                taken[arm] = taken.get(arm, 0) + 1
        for a, c in cross:
            # the curvature at the joint stands for half the first edge of each member
            # that ends there (a member running through it, or the rigid base, keeps its
            # own triples): springs in series, shared among the pairs an arm takes part in
            ending = [(arm, float(np.hypot(*(x0[arm[0]] - x0[joint])))) for arm in (a, c)
                      if arm[3]]
            if not ending:
                continue
            length = sum(0.5 * edge for _, edge in ending)
            compliance = sum(0.5 * edge / arm[2] for arm, edge in ending)
            triples.append((a[0], joint, c[0]))
            stiffness.append(length / compliance / max(taken[a], taken[c]))
            lengths.append(length)
    front = plan.front_nodes
    return FingerBody(
        name='fin_ray', rest_positions=x0, masses=masses,
        base_nodes=np.asarray(plan.base_nodes, dtype=np.int64),
        surface_edges=np.stack([front[:-1], front[1:]], axis=1),
        tip_node=int(plan.tip_node), depth=float(b),
        rod_edges=np.concatenate(edges), rod_axial_stiffness=np.concatenate(axial),
        bend_triples=np.array(triples, dtype=np.int64).reshape(-1, 3),
        bend_stiffness=np.array(stiffness), bend_lengths=np.array(lengths),
        youngs_modulus=e_mod, poisson_ratio=material.poisson_ratio)
