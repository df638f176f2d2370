"""Our Fin Ray finger against measured forces of a Fin Ray pressed onto a rigid cylinder.

Source (the only complete numeric case we have; a 2021 undergraduate thesis repository,
not a peer-reviewed paper): github.com/zeyang23/Fin-ray, ``Experiments/``:

- the finger (``test_05_20_1.m``, ``test_05_20_2.m``): two spring-steel strips 0.2 mm
  thick, 28 mm deep, E = 213 GPa; roots 73.24 mm apart on a clamped base, the front beam
  at 90 deg to it, the back beam at 116 deg, so that they meet at the tip: front beam
  73.24 / tan 26 deg = 150.16 mm, back beam 73.24 / sin 26 deg = 167.07 mm; 4 crossbeams
  joining the front beam at 27/54/81/108 mm and the back beam at 45.67/78.69/107.5/132.27
  mm from the base, modelled there as rigid links pinned to the strips (a fixed distance
  between the two points, a force along the link, no moment: ``finray_force.m``);
- the load (``test_05_20_1.m``): a rigid cylinder, its centre 66.5 mm from the base along
  the front beam, touching it at delta 0; the base moved towards it by delta; frictionless
  point contacts;
- the figures (``test_05_20_plot.m``): the sensor's force components [tangential; normal]
  at delta 5..30 mm and their model's |F|, for a cylinder of radius 20 mm and one of
  30 mm (their model ran it as 31.5 mm; the 20 mm case's result file is named r22.5).

Our finger: ``gripper.finger.fin_ray.*`` with the crossbeams as ``rib_ends`` and
``rib_joint: pinned``, ribs of 3 mm steel (EA 1.8e7 N, 75x the strips': rigid links),
a custom material of 213 GPa; the tip 0.4 mm inside the front corner (our geometry keeps
the beams two thicknesses apart at the tip: the front beam leans 0.15 deg). The cylinder
(``core.finger_indent``) moves into the front beam perpendicular to it in 0.5 mm steps,
touching its surface (0.1 mm off the centre line) at delta 0.

    python bench/fin_ray_published.py [--radius 0.02] [--model-radius R] [--element 0.001]
        [--e-scaling] [--source-model] [--plate] [--friction MU]

``--plate`` bends the strips as plates (``gripper.finger.fin_ray.section: plate``), E t^3
b / (12 (1 - nu^2)) with steel's nu 0.3, instead of beams (E t^3 b / 12): a strip 28 mm
wide and 0.2 mm thick curved to a radius R has Searle's parameter b^2 / (R t) = 39 at R
= 100 mm, far above the ~1 below which it would bend as a beam (its cross-section free
to curl anticlastically); our 3D Fin Ray bends its members as plates so. ``--friction
MU`` gives the cylinder contact Coulomb friction (``finger_indent.DiscFriction``): the
source's model is frictionless, its experiment was not; the sensor's tangential force is
the figure that tells mu.

``--e-scaling`` applies the source model's stiffening of the strips (E x L_front / 135 mm
and E x L_back / 156 mm, undocumented there); ``--model-radius`` runs another radius than
the cylinder's (their 22.5 / 31.5 mm) against the same measurements.

``--source-model`` runs the source model's own inputs as its code computes them: the E
scaling, its radius (22.5 / 31.5 mm), and its crossbeams where its discretisation puts
them. That model cuts each strip into 50 segments and joins a crossbeam at the end of
segment fix(50 x distance / strip length), up to one segment (3.0 mm on the front strip,
3.3 mm on the back) nearer the base than the nominal distances, while the crossbeam's
length stays the nominal one: 1.2-1.5 mm (2-7 %) shorter than the distance between the
points it joins, so the finger is prestressed before the cylinder touches it. Ours then
takes the same attachment points and the same rib rest lengths (``rod_rest_lengths``).
Its saved runs (``Experiments/X_series_r22.5_delta30.mat``, which ``test_05_20_2.m``
loads for the 20 mm cylinder, and ``X_series_r31.5_delta35.mat``: three contact points
per delta, each its position and normal force) give the sum of its contact forces'
magnitudes, which the table sets beside the sum of ours.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time

import numpy as np

from gripper_sim.configuration import load_config
from gripper_sim.core.barrier import BarrierSettings
from gripper_sim.core.fin_ray import fin_ray_from_config
from gripper_sim.core.finger_indent import front_beam_disc, indent_disc
from gripper_sim.core.stepper import NewtonFailure
from gripper_sim.geometry.fin_ray import FinRayGeometry, layout

STRIP = 0.2e-3             # m, strip thickness
DEPTH = 28e-3              # m
STEEL = 213e9              # Pa
#: spring steel's Poisson ratio (the usual 0.3 of steels): its plate bending (``--plate``)
STEEL_POISSON = 0.3
ROOTS = 73.24e-3           # m, between the beams' roots on the base
PSI = math.radians(26.0)   # between the beams
FRONT = ROOTS / math.tan(PSI)   # 150.16 mm
BACK = ROOTS / math.sin(PSI)    # 167.07 mm
#: per crossbeam (along the back beam, along the front beam), m from the base
RIB_ENDS = ((45.67e-3, 27e-3), (78.69e-3, 54e-3), (107.5e-3, 81e-3), (132.27e-3, 108e-3))
CONTACT_HEIGHT = 66.5e-3   # m, the cylinder's centre from the base along the front beam
RIB_THICKNESS = 3e-3       # m of steel: rigid links
DELTAS = (5e-3, 10e-3, 15e-3, 20e-3, 25e-3, 30e-3)
#: test_05_20_plot.m: cylinder radius (m) -> (sensor [tangential, normal] N at DELTAS,
#: their model's |F| N, the radius their model ran)
MEASURED = {
    0.020: (((0.36, 1.45), (0.39, 2.92), (0.43, 4.65), (0.85, 6.50), (1.03, 9.36),
             (1.10, 13.58)), (1.51, 2.95, 4.54, 6.44, 9.10, 13.58), 0.0225),
    0.030: (((0.30, 1.15), (0.37, 2.46), (0.30, 4.19), (0.25, 6.34), (0.35, 9.00),
             (0.80, 12.60)), (1.24, 2.67, 4.24, 6.06, 8.33, 12.81), 0.0315),
}
#: the source's saved model runs (module docstring): the sum of its three contact forces'
#: magnitudes, N at DELTAS, by the radius it ran
SAVED_RUNS = {
    0.0225: (1.238, 2.649, 4.202, 6.024, 8.415, 12.479),
    0.0315: (1.243, 2.672, 4.247, 6.054, 8.373, 13.104),
}
#: segments per strip of the source model (``nA``, ``nB``)
SOURCE_SEGMENTS = 50
#: the cylinder contact: a node pressed with 1 N stays about 20 um from the cylinder
#: (2 kappa dhat / F), at most dhat = 10 um (0.2 % of delta 5 mm)
CONTACT = BarrierSettings(dhat=1e-5, stiffness=1.0)


def thesis_config(element_length: float = 1e-3, rib_ends=RIB_ENDS, section: str = 'beam'):
    """The flat configuration of the source's finger (module docstring), with its
    crossbeams at ``rib_ends`` ((back, front) m from the base, per crossbeam), its members
    bending as ``section`` (``gripper.finger.fin_ray.section``)."""
    prefix = 'gripper.finger.fin_ray.'
    values = {'length': FRONT, 'base_width': ROOTS, 'tip_offset': ROOTS - 2 * STRIP,
              'depth': DEPTH, 'beam_thickness': STRIP, 'rib_thickness': RIB_THICKNESS,
              'rib_ends': json.dumps([list(pair) for pair in rib_ends]),
              'rib_joint': 'pinned', 'element_length': element_length,
              'material': 'custom', 'youngs_modulus': STEEL, 'density': 7850.0,
              'poisson_ratio': STEEL_POISSON, 'section': section}
    return load_config(overrides=['gripper.finger.type=fin_ray']
                       + [f'{prefix}{k}={v}' for k, v in values.items()])


def scale_strips(body, geometry: FinRayGeometry, front: float, back: float):
    """The body with the bending stiffness of the front and back beams' own triples
    scaled by ``front`` and ``back`` (the source model's E scaling)."""
    members = {m.name: set(m.nodes.tolist()) for m in layout(geometry).members}
    stiffness = body.bend_stiffness.copy()
    for k, triple in enumerate(body.bend_triples.tolist()):
        for name, factor in (('front', front), ('back', back)):
            if set(triple) <= members[name]:
                stiffness[k] *= factor
    return dataclasses.replace(body, bend_stiffness=stiffness)


def crossbeam_length(back: float, front: float) -> float:
    """m, the distance between the points ``back`` and ``front`` m from the base along the
    unloaded back and front strips (the triangle they make with the tip)."""
    a, b = FRONT - front, BACK - back
    return math.sqrt(a * a + b * b - 2.0 * a * b * math.cos(PSI))


def source_rib_ends() -> tuple[tuple[float, float], ...]:
    """(back, front) m from the base per crossbeam, where the source model joins them: at
    the end of segment fix(segments x distance / strip length) of each strip."""
    def snapped(distance, strip):
        return int(SOURCE_SEGMENTS * distance / strip) * strip / SOURCE_SEGMENTS
    return tuple((snapped(back, BACK), snapped(front, FRONT)) for back, front in RIB_ENDS)


def prestress_ribs(body, geometry: FinRayGeometry, rest_lengths):
    """The body with each rib's rod edges at their drawn length scaled by the rib's
    ``rest_lengths`` (m, per rib) over its drawn length: ribs that pull (shorter) or push."""
    members = layout(geometry).members
    drawn = np.linalg.norm(body.rest_positions[body.rod_edges[:, 1]]
                           - body.rest_positions[body.rod_edges[:, 0]], axis=1)
    rest = drawn.copy()
    ribs = iter(rest_lengths)
    start = 0
    for member in members:                 # fin_ray_body's edges: member after member
        count = len(member.nodes) - 1
        if member.name.startswith('rib'):
            ends = body.rest_positions[member.nodes[[0, -1]]]
            rest[start:start + count] *= next(ribs) / np.linalg.norm(ends[1] - ends[0])
        start += count
    return dataclasses.replace(body, rod_rest_lengths=rest)


def run(radius: float, element_length: float = 1e-3, e_scaling: bool = False,
        step: float = 0.5e-3, travel: float = 30e-3, retries: int = 2,
        source_ribs: bool = False, friction: float = 0.0, plate: bool = False):
    """(Indentation, body) of the source's finger pressed by a cylinder of ``radius`` m
    to ``travel`` m in ``step`` m increments; an increment Newton cannot solve makes the
    run start again with half the step (``retries`` times: the E-scaled finger on the
    22.5 mm cylinder needs 0.25 mm steps with 1 mm elements). ``source_ribs``: the
    crossbeams where the source model joins them, prestressed as there. ``friction``:
    mu of the cylinder contact. ``plate``: the strips bend as plates (module doc)."""
    try:
        return _run(radius, element_length, e_scaling, step, travel, source_ribs, friction,
                    plate)
    except NewtonFailure as failure:
        if retries <= 0:
            raise
        print(f'({failure} at {step * 1e3:g} mm steps: again at {step * 0.5e3:g} mm)')
        return run(radius, element_length, e_scaling, 0.5 * step, travel, retries - 1,
                   source_ribs, friction, plate)


def _run(radius: float, element_length: float, e_scaling: bool, step: float,
         travel: float, source_ribs: bool, friction: float = 0.0, plate: bool = False):
    """``run`` at one step size."""
    ends = source_rib_ends() if source_ribs else RIB_ENDS
    config = thesis_config(element_length, ends, 'plate' if plate else 'beam')
    body = fin_ray_from_config(config, DEPTH)
    geometry = FinRayGeometry.from_config(config, DEPTH)
    if source_ribs:
        body = prestress_ribs(body, geometry, [crossbeam_length(*pair) for pair in RIB_ENDS])
    if e_scaling:
        body = scale_strips(body, geometry, FRONT / 135e-3, BACK / 156e-3)
    touching, centre, _normal = front_beam_disc(body, layout(geometry).front_nodes,
                                                CONTACT_HEIGHT, radius + 0.5 * STRIP)
    result = indent_disc(body, touching, centre, radius + 0.5 * STRIP,
                         np.array([-1.0, 0.0]), travel, round(travel / step), CONTACT,
                         friction=friction)
    return result, body


def table(radius: float, model_radius: float, element_length: float, e_scaling: bool,
          source_ribs: bool = False, friction: float = 0.0, plate: bool = False):
    """Prints the comparison; returns the rows (delta m, our (Fx, Fz) N, measured |F| N,
    error of our |F| against it, our sum of contact force magnitudes N)."""
    sensor, theirs, their_radius = MEASURED[radius]
    saved = SAVED_RUNS.get(model_radius) if source_ribs else None
    start = time.process_time()
    result, body = run(model_radius, element_length, e_scaling, source_ribs=source_ribs,
                       friction=friction, plate=plate)
    cpu = time.process_time() - start
    print(f'cylinder r = {radius * 1e3:g} mm (model r = {model_radius * 1e3:g} mm; the source '
          f'model ran {their_radius * 1e3:g} mm), elements {element_length * 1e3:g} mm, '
          f'{body.n_nodes} nodes, E scaling {"on" if e_scaling else "off"}, crossbeams '
          f'{"as the source model joins them" if source_ribs else "nominal"}, strips bent as '
          f'{"plates" if plate else "beams"}, friction mu = {friction:g}, CPU {cpu:.1f} s')
    print(f'base reaction at the end {result.reaction.round(3)} N (minus the force on the '
          'cylinder)')
    saved_head = ' | ours sum|f| saved run' if saved else ''
    print(' delta mm | ours Fx   Fz    |F| N | measured Ft   Fn   |F| N | their model |F| | '
          'ours vs measured' + saved_head)
    rows = []
    for k, delta in enumerate(DELTAS):
        i = int(np.argmin(np.abs(result.delta - delta)))
        fx, fz = result.force[i]                  # on the cylinder, +x: pushed away
        ours = math.hypot(fx, fz)
        measured = math.hypot(*sensor[k])
        error = ours / measured - 1.0
        rows.append((delta, (fx, fz), measured, error, result.pressing[i]))
        saved_cells = (f' | {result.pressing[i]:11.2f} {saved[k]:9.2f}' if saved else '')
        print(f'{delta * 1e3:8.0f} | {fx:6.2f} {fz:6.2f} {ours:6.2f} | {sensor[k][0]:10.2f} '
              f'{sensor[k][1]:5.2f} {measured:6.2f} | {theirs[k]:15.2f} | '
              f'{error * 100:+6.1f} %' + saved_cells)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--radius', type=float, default=0.02, choices=sorted(MEASURED),
                        help='m, the measured cylinder')
    parser.add_argument('--model-radius', type=float, default=None,
                        help='m, the radius to model (default: the cylinder\'s)')
    parser.add_argument('--element', type=float, default=1e-3, help='m, element length')
    parser.add_argument('--e-scaling', action='store_true',
                        help='the source model\'s E x L/135 mm, L/156 mm')
    parser.add_argument('--source-model', action='store_true',
                        help='the source model\'s inputs: E scaling, its radius, its '
                             'crossbeams (module docstring)')
    parser.add_argument('--friction', type=float, default=0.0,
                        help='mu of the cylinder contact (default 0: frictionless)')
    parser.add_argument('--plate', action='store_true',
                        help='the strips bend as plates: E / (1 - nu^2), nu = 0.3')
    args = parser.parse_args(argv)
    if not (math.isfinite(args.friction) and args.friction >= 0.0):
        parser.error(f'--friction {args.friction}: must be a number >= 0')
    if args.source_model:
        table(args.radius, args.model_radius or MEASURED[args.radius][2], args.element,
              True, source_ribs=True)
    else:
        table(args.radius, args.model_radius or args.radius, args.element, args.e_scaling,
              friction=args.friction, plate=args.plate)
    return 0


if __name__ == '__main__':
    sys.exit(main())
