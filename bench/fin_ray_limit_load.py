"""The default Fin Ray finger's limit load: pressed by a rigid disc, where does its force
stop growing? Prints figures; asserts nothing.

The 3D Fin Ray gives way under the default apple at 76-78 N of grip, its tip swinging
back and up (README, *Fingers and soft pads*). This asks whether the finger's own frame
has such a limit, independently of the 3D solver and the fruit: the planar finger's
statics (``core.finger_statics``; the ``gripper.finger.fin_ray.*`` defaults, printed TPU,
``--depth`` deep) with its base held, pressed by a fixed rigid disc of the apple's radius
(``core.finger_indent``, frictionless) perpendicular to the front beam in ``--step``
increments, its centre ``--heights`` from the base corner along the beam. By default the
beams and ribs bend as plates, E t^3 / (12 (1 - nu^2)) per unit width, as the 3D
finger's shells do (``--beam``: E t^3 / 12, the planar finger's own). For each height it
prints the limit of the force on the disc against its travel: the largest force before
the first fall (a limit point: the frame snaps), else where the force stops growing (the
first travel with less than 5 % more force over the next millimetre: a plateau), with the
tip's move there (x: away from the jaw, towards the fruit). Past a limit, or where there
is none (pressed near the base), the front beam folds onto the ribs and the back beam and
the force climbs steeply: those figures are the folded finger's, not a grasp's.

Usage::

    python bench/fin_ray_limit_load.py [--heights 0.02 0.03 0.04 0.05] [--depth 0.04]
        [--radius 0.03175] [--travel 0.02] [--step 0.0005] [--beam]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np

from gripper_sim.configuration import load_config
from gripper_sim.core.barrier import BarrierSettings
from gripper_sim.core.fin_ray import fin_ray_from_config, material_from_config
from gripper_sim.core.finger_indent import front_beam_disc, indent_disc
from gripper_sim.core.stepper import NewtonFailure
from gripper_sim.geometry.fin_ray import FinRayGeometry, layout

#: the disc contact (as ``fin_ray_published.py``'s) and the finger's self-contact (the
#: simulation's ``contact.ipc`` defaults)
CONTACT = BarrierSettings(dhat=1e-5, stiffness=1.0)
SELF_CONTACT = BarrierSettings(dhat=1e-6, stiffness=0.1)


def press(height: float, depth: float, radius: float, travel: float, step: float,
          plate: bool):
    """(Indentation, the front beam's nodes tip first, the body) of the default finger
    pressed at ``height`` m; halves the step (twice) where Newton finds no equilibrium."""
    config = load_config(overrides=['gripper.finger.type=fin_ray',
                                    'gripper.finger.fin_ray.element_length=0.001'])
    body = fin_ray_from_config(config, depth)
    if plate:
        nu = material_from_config(config).poisson_ratio
        body = dataclasses.replace(body, bend_stiffness=body.bend_stiffness / (1 - nu * nu))
    front = layout(FinRayGeometry.from_config(config, depth)).front_nodes
    offset = 0.5 * config['gripper.finger.fin_ray.beam_thickness']
    nodes, centre, normal = front_beam_disc(body, front, height, radius + offset)
    for attempt in range(3):
        try:
            return indent_disc(body, nodes, centre, radius + offset, -normal, travel,
                               round(travel / step), CONTACT, SELF_CONTACT), front, body
        except NewtonFailure:
            if attempt == 2:
                raise
            step *= 0.5


def limit(delta: np.ndarray, force: np.ndarray) -> tuple[int, str]:
    """(index, kind) of the limit of a force curve: the first local maximum ('peak'),
    else the first point whose force grows less than 5 % over the next millimetre
    ('plateau'), else the last point ('none')."""
    falls = np.nonzero(np.diff(force) < 0)[0]
    if len(falls):
        return int(falls[0]), 'peak'
    for i, d in enumerate(delta):
        ahead = np.nonzero(delta >= d + 1e-3)[0]
        if len(ahead) and force[ahead[0]] < 1.05 * force[i]:
            return i, 'plateau'
    return len(delta) - 1, 'none'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--heights', type=float, nargs='+', default=[0.02, 0.03, 0.04, 0.05],
                        help='m, the disc centre from the base corner along the front beam')
    parser.add_argument('--depth', type=float, default=0.04,
                        help='m, the finger\'s width (default: the 3D jaw width)')
    parser.add_argument('--radius', type=float, default=0.03175,
                        help='m, the disc (default: the apple\'s)')
    parser.add_argument('--travel', type=float, default=0.02, help='m, the last delta')
    parser.add_argument('--step', type=float, default=5e-4, help='m per increment')
    parser.add_argument('--beam', action='store_true',
                        help='bend as beams (E t^3 / 12), not plates')
    args = parser.parse_args(argv)
    print(f"default Fin Ray, {args.depth * 1e3:g} mm deep, {'beam' if args.beam else 'plate'} "
          f'bending, rigid disc r = {args.radius * 1e3:g} mm')
    print(' height mm | limit     | force N | at delta mm | tip move x, z mm | CPU s')
    for height in args.heights:
        start = time.process_time()
        try:
            result, front, body = press(height, args.depth, args.radius, args.travel,
                                        args.step, not args.beam)
        except NewtonFailure as failure:
            print(f'{height * 1e3:10.0f} | no equilibrium found ({failure})')
            continue
        force = np.hypot(*result.force.T)
        i, kind = limit(result.delta, force)
        if kind == 'none':
            print(f'{height * 1e3:10.0f} | none up to a travel of {args.travel * 1e3:g} mm '
                  '(the front beam folds onto the finger)')
            continue
        tip = result.positions[i, front[0]] - body.rest_positions[front[0]]
        print(f'{height * 1e3:10.0f} | {kind:9s} | {force[i]:7.2f} | {result.delta[i] * 1e3:11.1f}'
              f' | {tip[0] * 1e3:+7.2f} {tip[1] * 1e3:+7.2f}  | '
              f'{time.process_time() - start:5.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
