"""Simulation configuration: the schema, YAML presets, ``--set`` overrides, validation.

A configuration is a nested mapping (YAML) whose every leaf is described in
``SCHEMA`` with its unit, range and meaning. Presets live in ``config/fruits``;
``load_config`` merges, in order, the embedded defaults, a fruit preset (always one:
``--fruit``, else the file's ``fruit:``, else ``--set fruit=NAME``, else the default
fruit's), a finger preset, a file, and ``dotted.key=value`` overrides, and validates
the result. Unknown keys and values out of range raise ``ConfigError`` naming the key;
a key set by the user that has no effect in the set-up (``NO_EFFECT``) is a
``ConfigWarning`` naming the key that does (``no_effect_reason``).
"""
from __future__ import annotations

import copy
import functools
import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from gripper_sim.errors import ConfigError, ConfigWarning
from gripper_sim.geometry.fin_ray import check_fin_ray
from gripper_sim.geometry.fin_ray import resolution_warning as fin_ray_resolution_warning
from gripper_sim.geometry.finger_materials import MATERIAL_NAMES, SECTIONS as FIN_RAY_SECTIONS
from gripper_sim.geometry.fingers import check_finger
from gripper_sim.geometry.shapes import outline_from_config
from gripper_sim.geometry.solid_pad import check_solid_pad

DEFAULT_FRUIT = 'apple'
#: file name endings that make a ``--fruit`` value a preset file rather than a name
PRESET_SUFFIXES = ('.yaml', '.yml')
#: top-level section of a preset file that records where it came from (not configuration)
PROVENANCE_KEY = 'calibration'
#: keys that select a preset (in a file's top level, a scenario, ``--set fruit=plum``)
#: rather than set a value
SELECTORS = ('fruit', 'finger')
#: the finger types whose faces are rigid (the others are deformable bodies)
RIGID_FINGERS = ('flat', 'arc', 'vgroove')
#: a value kind (``Key.kind``) as an error message names it
KIND_NAMES = {'float': 'a number', 'int': 'an integer', 'bool': 'true or false',
              'str': 'a string', 'list': 'a list'}


@dataclass(frozen=True)
class Key:
    """One configuration leaf.

    Attributes:
        default: value used when nothing sets it (None where ``nullable``).
        unit: SI unit, '' for dimensionless, '-' for text or flags.
        description: what it means, for the README and error messages.
        kind: 'float', 'int', 'bool', 'str' or 'list'.
        low, high: inclusive range for numbers.
        choices: allowed values for text.
        nullable: None is allowed (meaning: derive it, see description).
        open_low: the lower bound itself is not allowed (e.g. > 0).
        default_3d: the default when ``dimension`` is 3, where it differs (None: the
            same as ``default``).
        runtime: the key may change while a simulation runs (``RUNTIME_KEYS``: the
            node's dynamic parameters, ``set_parameter``); every other key is fixed
            when the simulation is built.
    """

    default: Any
    unit: str
    description: str
    kind: str = 'float'
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    nullable: bool = False
    open_low: bool = False
    default_3d: Any = None
    runtime: bool = False


SCHEMA: dict[str, Key] = {
    'dimension': Key(2, '-', 'model dimension; 2 = planar x-z model (per unit depth); '
                     '3 = the 3D model (surface or tetrahedral meshes, see fruit.mesh.*)',
                     'int', 2, 3),
    # --- fruit
    'fruit.name': Key('apple', '-', 'name shown in outputs', 'str'),
    'fruit.model': Key('shell', '-', 'shell: skin ring + enclosed-area pressure; '
                       'solid: triangle-meshed neo-Hookean flesh (+ optional skin ring); '
                       'point: a single point mass (contact and bouncing checks)',
                       'str', choices=('shell', 'solid', 'point')),
    'fruit.shape.type': Key('circle', '-', 'rest outline: circle; ellipse; egg (ovoid); '
                            'points (closed polygon through fruit.shape.points); spline '
                            '(periodic cubic spline through fruit.shape.points)', 'str',
                            choices=('circle', 'ellipse', 'egg', 'points', 'spline')),
    'fruit.shape.diameter': Key(0.0635, 'm', 'outline diameter (circle); width along the '
                                "shape's own x axis (ellipse, egg); not used by points/spline",
                                low=0.005, high=0.5),
    'fruit.shape.height': Key(None, 'm', "ellipse, egg: extent along the shape's own z "
                              'axis; null = the diameter', low=0.005, high=0.5,
                              nullable=True),
    'fruit.shape.taper': Key(0.15, '', 'egg: asymmetry k of the ovoid x = a cos t (1 - k '
                             'sin t), z = b sin t (0 = ellipse; the narrow end is up)',
                             low=0.0, high=0.45),
    'fruit.shape.points': Key('', 'm', 'points, spline: the outline as a list of [x, z] '
                              'pairs (YAML list, stored as its JSON text), in order around '
                              'the outline; at least 3 (points) or 4 (spline) distinct pairs; '
                              'it must not cross itself', 'str'),
    'fruit.shape.angle': Key(0.0, 'deg', 'rotation of the outline about its centroid, '
                             'counter-clockwise in the x-z plane (0: own x axis along the '
                             'jaw closing axis)', low=-360.0, high=360.0),
    'fruit.depth': Key(None, 'm', 'out-of-plane depth b that turns the planar model '
                       'into N and kg; null = 2/3 of the diameter, which gives a disk '
                       'the mass of the sphere', low=1e-4, high=1.0, nullable=True,
                       open_low=True),
    'fruit.density': Key(1000.0, 'kg/m^3', 'flesh density', low=50.0, high=5000.0),
    'fruit.nodes': Key(64, '-', 'skin (outline) node count', 'int', 8, 4096),
    'fruit.flesh.youngs_modulus': Key(2.0e6, 'Pa', 'flesh Young modulus E',
                                      low=1e3, high=1e10),
    'fruit.flesh.poisson_ratio': Key(0.385, '', 'flesh Poisson ratio nu', low=0.0,
                                     high=0.49),
    'fruit.flesh.mesh_grading': Key(1.25, '', 'solid model: ratio of successive ring '
                                    'spacings from the skin inwards (1 = uniform)',
                                    low=1.0, high=2.0),
    'fruit.shape.width': Key(None, 'm', '3D: extent of the body along y (along the jaw '
                             'faces); null = the outline revolved about z (circle: a '
                             'sphere)', low=0.005, high=0.5, nullable=True),
    'fruit.mesh.subdivisions': Key(8, '-', '3D: geodesic frequency f of the surface mesh '
                                   '(10 f^2 + 2 surface vertices; 8 gives 642)', 'int', 1,
                                   40),
    'fruit.mesh.jaw_refinement': Key(1.0, '', '3D: surface mesh spacing at the two jaw '
                                     'contact points (+/- x) over the uniform spacing '
                                     '(1 = uniform)', low=0.1, high=1.0),
    'fruit.mesh.max_tet_volume': Key(None, 'm^3', '3D solid model: largest tetrahedron: the '
                                     'mesher adds layers below the skin (1 to 4) until none '
                                     'is larger; null = 2 layers', low=0.0, high=1e-2,
                                     nullable=True, open_low=True),
    'fruit.mesh.order': Key(1, '-', '3D solid model: 1 = linear (4-node) tetrahedra; 2 = '
                            'quadratic (10-node) ones: far more accurate in contact (Hertz '
                            'force), more nodes and slower', 'int', 1, 2),
    'fruit.skin.enabled': Key(True, '-', 'solid model: add the skin ring on the '
                              'boundary (the shell model always has it)', 'bool'),
    'fruit.skin.youngs_modulus': Key(10.0e6, 'Pa', 'skin Young modulus E_s',
                                     low=1e3, high=1e11),
    'fruit.skin.thickness': Key(0.0005, 'm', 'skin thickness t', low=1e-6, high=0.05),
    'fruit.skin.poisson_ratio': Key(0.3, '', '3D: skin Poisson ratio (membrane and plate '
                                    'bending of the skin shell)', low=0.0, high=0.49),
    'fruit.skin.wrinkling': Key(False, '-', '3D: the skin wrinkles instead of carrying '
                                'in-plane compression (tension-field membrane: relaxed '
                                'SVK energy); for skins stiff in tension, E_s t >> p R',
                                'bool'),
    'fruit.pressure.turgor': Key(0.0, 'Pa', 'shell model: internal pressure at the '
                                 'rest area (gauge)', low=0.0, high=1e7),
    'fruit.pressure.bulk_modulus': Key(None, 'Pa', 'shell model: area bulk modulus K, '
                                       'p = turgor - K (A - A0) / A0; null = plane-strain '
                                       'bulk modulus of the flesh, E / (2 (1 + nu) '
                                       '(1 - 2 nu))', low=0.0, high=1e10, nullable=True),
    'fruit.damping.mass': Key(0.0, '1/s', 'Rayleigh mass-proportional damping alpha',
                              low=0.0, high=1e4),
    'fruit.damping.stiffness': Key(0.0, 's', 'Rayleigh stiffness-proportional damping '
                                   'beta (on the elastic Hessian at the step start): the '
                                   'flesh\'s viscosity, which damps a gripped fruit\'s '
                                   'ringing (~70 Hz for the apple) so that a pick converges '
                                   'in dt; 0: elastic, it rings as long as the integrator '
                                   'lets it (README, Jaws)',
                                   low=0.0, high=1.0),
    # from 1 kPa: a figure in MPa (0.26) is refused, not taken as a fruit that bruises
    # at any touch
    'fruit.bruise_pressure': Key(0.26e6, 'Pa', 'contact pressure above which the '
                                 'fruit bruises', low=1e3, high=1e9),
    'fruit.failure_stress': Key(0.29e6, 'Pa', 'flesh failure stress (crushing)',
                                low=1e3, high=1e9),
    'fruit.failure_strain': Key(None, '', 'whole-fruit compression (width loss over the '
                                'rest width) at which the flesh fails (crushing); null = '
                                'not checked', low=0.0, high=1.0, nullable=True,
                                open_low=True),
    'fruit.initial_velocity.x': Key(0.0, 'm/s', 'initial velocity of every node, x',
                                    low=-100.0, high=100.0),
    'fruit.initial_velocity.z': Key(0.0, 'm/s', 'initial velocity of every node, z',
                                    low=-100.0, high=100.0),
    'fruit.initial_height': Key(None, 'm', 'height of the fruit centre; null = resting '
                                'on the table (settled under its weight before t = 0; or 0 '
                                'without a table)', low=-10.0, high=10.0, nullable=True),
    # --- gripper
    'gripper.initial_gap': Key(None, 'm', 'jaw gap at start (deformable fingers: between '
                               'their backings); not less than the gap at which the fingers '
                               "touch the fruit (rigid faces, pads: the fruit's width across "
                               'them); null = that gap + 10 mm, at most gripper.max_gap',
                               low=0.0, high=1.0, nullable=True),
    'gripper.max_gap': Key(0.2, 'm', 'largest gap the jaws can open to (the fruit must fit '
                           'between the fingers there)', low=0.001, high=2.0),
    'gripper.jaw_height': Key(0.04, 'm', 'length of the jaw face along z', low=1e-3,
                              high=1.0),
    'gripper.jaw_width': Key(0.04, 'm', '3D: width of the jaw face along y', low=1e-3,
                             high=1.0),
    'gripper.jaw_thickness': Key(0.01, 'm', 'jaw thickness along x (nodes deeper '
                                 'than this behind the face are not in contact)',
                                 low=1e-4, high=0.5),
    'gripper.initial_lift': Key(None, 'm', 'height of the jaw centre at start; null = '
                                'the fruit centre height', low=-10.0, high=10.0,
                                nullable=True),
    'gripper.close_speed': Key(0.02, 'm/s', 'default gap closing rate', low=1e-5,
                               high=1.0, open_low=True, runtime=True),
    'gripper.max_speed': Key(0.2, 'm/s', 'largest gap rate a command may ask for',
                             low=1e-5, high=5.0),
    'gripper.force_damping': Key(0.0, 'N s/m', 'force mode, holding a grip: the drive\'s '
                                 'damping c, grip force - command = c x gap rate (a jaw '
                                 'on a force-limited motor with damping; 0: an ideal force '
                                 'source)', low=0.0, high=1e4),
    'gripper.lift_speed': Key(0.05, 'm/s', 'default lift speed', low=1e-5, high=2.0, runtime=True),
    'gripper.lift_acceleration': Key(0.5, 'm/s^2', 'acceleration limit of the lift '
                                     '(trapezoidal speed profile)', low=1e-3, high=100.0),
    'gripper.max_force': Key(200.0, 'N', 'largest grip force a command may ask for',
                             low=0.0, high=1e5, open_low=True),
    'gripper.transport_speed': Key(0.1, 'm/s', 'default speed of the sideways transport '
                                   '(x translation of both jaws)', low=1e-5, high=5.0,
                                   open_low=True),
    'gripper.transport_acceleration': Key(1.0, 'm/s^2', 'acceleration limit of the '
                                          'transport (trapezoidal speed profile)',
                                          low=1e-3, high=100.0),
    'gripper.finger.name': Key('flat', '-', 'name of the finger shown in outputs', 'str'),
    'gripper.finger.type': Key('flat', '-', 'jaw face profile in the x-z plane: flat; arc '
                               '(concave circular arc of radius gripper.finger.radius); '
                               'vgroove (a V of opening gripper.finger.groove_angle); '
                               'solid_pad (a deformable elastic block on the jaw, '
                               'gripper.finger.solid_pad.*; 3D: as wide as '
                               'gripper.jaw_width); fin_ray (a deformable Fin Ray finger, '
                               'gripper.finger.fin_ray.*; 3D: extruded into thin shells)',
                               'str',
                               choices=RIGID_FINGERS + ('solid_pad', 'fin_ray')),
    'gripper.finger.radius': Key(0.05, 'm', 'arc: radius of the concave face (its chord is '
                                 'gripper.jaw_height)', low=1e-3, high=10.0),
    'gripper.finger.groove_angle': Key(120.0, 'deg', 'vgroove: opening angle between the '
                                       'two flanks (180 = flat)', low=30.0, high=179.0),
    'gripper.finger.segments': Key(8, '-', 'arc: number of flat facets the arc is made '
                                   'of', 'int', 2, 64),
    'gripper.finger.fin_ray.length': Key(0.06, 'm', 'fin_ray: height of the finger along z '
                                         '(base on the jaw at the top, tip at the bottom)',
                                         low=0.01, high=0.5),
    'gripper.finger.fin_ray.base_width': Key(0.025, 'm', 'fin_ray: width of the base along x '
                                             '(how far the front beam stands out of the '
                                             'jaw at the base)', low=0.002, high=0.2),
    'gripper.finger.fin_ray.depth': Key(None, 'm', 'fin_ray: width of the finger along the '
                                        'jaw (out of the plane); null = the fruit\'s depth '
                                        '(fruit.depth), as the planar model assumes; 3D: '
                                        'null = gripper.jaw_width',
                                        low=1e-3, high=0.5, nullable=True),
    'gripper.finger.fin_ray.beam_thickness': Key(0.0012, 'm', 'fin_ray: thickness of the '
                                                 'front and back beams', low=0.0, high=0.02,
                                                 open_low=True),
    'gripper.finger.fin_ray.rib_thickness': Key(0.0008, 'm', 'fin_ray: thickness of each rib',
                                                low=0.0, high=0.02, open_low=True),
    'gripper.finger.fin_ray.rib_count': Key(4, '-', 'fin_ray: number of ribs (cross beams), '
                                            'equally spaced along the back beam', 'int', 1,
                                            40),
    'gripper.finger.fin_ray.rib_angle': Key(None, 'deg', 'fin_ray: angle of the ribs to the '
                                            'base (0: parallel to it; positive: front ends '
                                            'towards the tip); null = perpendicular to the '
                                            'back beam', low=-60.0, high=60.0,
                                            nullable=True),
    'gripper.finger.fin_ray.rib_ends': Key(None, 'm', 'fin_ray: the ribs as a list of '
                                           '[back, front] pairs, one per rib: where it meets '
                                           'the back and the front beam, as distances from '
                                           'the base along each beam (YAML list, stored as '
                                           'its JSON text); it sets the rib count (rib_count '
                                           'and rib_angle are then not used); null = '
                                           'rib_count ribs by rib_angle', 'str',
                                           nullable=True),
    'gripper.finger.fin_ray.rib_joint': Key('rigid', '-', 'fin_ray: how the ribs join the '
                                            'beams: rigid (welded, the rest angle kept); '
                                            'pinned (hinged, no moment)', 'str',
                                            choices=('rigid', 'pinned')),
    'gripper.finger.fin_ray.tip_offset': Key(0.02, 'm', 'fin_ray: x of the tip (0: the back '
                                             'beam runs along the jaw; near base_width: the '
                                             'front beam nearly parallel to the jaw)',
                                             low=0.0, high=0.2),
    'gripper.finger.fin_ray.element_length': Key(None, 'm', 'fin_ray: rod element length '
                                                 'of the discretisation (at most 1000 nodes '
                                                 'in a finger: finer is refused); null = '
                                                 'follow the fruit: in 2D the coarsest of '
                                                 '4, 2, 1, 0.5 mm no longer than 1.5 times '
                                                 "the fruit outline's node spacing and a "
                                                 "quarter of the finger's length (4 mm for "
                                                 'the default apple), in 3D 2 mm',
                                                 low=0.0, high=0.05, nullable=True,
                                                 open_low=True),
    'gripper.finger.fin_ray.material': Key('tpu', '-', 'fin_ray: tpu (printed TPU, E = 100 '
                                           'MPa); silicone (Dragon Skin 30, E = 0.59 MPa); '
                                           'custom (gripper.finger.fin_ray.youngs_modulus '
                                           'and density)', 'str', choices=MATERIAL_NAMES),
    'gripper.finger.fin_ray.youngs_modulus': Key(None, 'Pa', 'fin_ray, custom material: '
                                                 'Young modulus E', low=1e3, high=1e12,
                                                 nullable=True),
    'gripper.finger.fin_ray.density': Key(1200.0, 'kg/m^3', 'fin_ray, custom material: '
                                          'density', low=50.0, high=20000.0),
    'gripper.finger.fin_ray.poisson_ratio': Key(0.45, '-', 'fin_ray, custom material: '
                                                'Poisson ratio nu (plate bending: section '
                                                'plate in 2D, the shells in 3D)', low=0.0,
                                                high=0.49),
    'gripper.finger.fin_ray.section': Key('beam', '-', 'fin_ray, 2D: how the beams and ribs '
                                          'bend over the finger\'s depth b: beam (plane '
                                          'stress, E t^3 b / 12: a member free to curl '
                                          'across its width); plate (plane strain, E t^3 b / '
                                          '(12 (1 - nu^2)), stretching E t b / (1 - nu^2): a '
                                          'member much wider than thick, bent to radii R '
                                          'with b^2 / (R t) >> 1, as the 3D shells bend)',
                                          'str', choices=FIN_RAY_SECTIONS),
    'gripper.finger.fin_ray.contact_dhat': Key(None, 'm', 'fin_ray, 3D: barrier activation '
                                               'distance of the fruit contact (and the '
                                               "table's, in the same barrier); null = 1e-4 "
                                               "(within the front beam's half thickness: the "
                                               'contact acts on its mid-surface); 2D: '
                                               'contact.ipc.dhat', low=1e-9, high=1e-3,
                                               nullable=True),
    'gripper.finger.pad.enabled': Key(False, '-', 'a soft elastic pad (silicone-like) on '
                                      'the jaw face', 'bool'),
    'gripper.finger.pad.thickness': Key(0.003, 'm', 'pad thickness t', low=0.0, high=0.05,
                                        open_low=True),
    'gripper.finger.pad.youngs_modulus': Key(1.0e6, 'Pa', 'pad Young modulus E_p '
                                             '(silicone rubber ~0.1-3 MPa, estimate)',
                                             low=1e3, high=1e9),
    'gripper.finger.pad.poisson_ratio': Key(0.45, '', 'pad Poisson ratio nu_p (< 0.5: the '
                                            'elastic-foundation pad model needs a '
                                            'compressible layer)', low=0.0, high=0.475),
    # solid pad sources: Smooth-On technical bulletins, 100 % tensile modulus (a secant
    # modulus near the small-strain E of these rubbers): Ecoflex 00-30 10 psi (69 kPa),
    # Dragon Skin 10 22 psi (152 kPa), Dragon Skin 30 86 psi (593 kPa), specific gravity
    # 1.07-1.08; Sylgard 184 (PDMS) E = 1.32-2.97 MPa by curing temperature (Johnston et
    # al. 2014, J. Micromech. Microeng. 24 035017)
    'gripper.finger.solid_pad.thickness': Key(0.006, 'm', 'solid_pad: thickness t of the '
                                              'block from the jaw backing to its front face '
                                              '(its height is gripper.jaw_height; its '
                                              'cells across it, thickness / layers, at '
                                              'least 1/400 of that: thinner is refused)',
                                              low=0.0,
                                              high=0.05, open_low=True),
    'gripper.finger.solid_pad.youngs_modulus': Key(
        0.593e6, 'Pa', 'solid_pad: Young modulus E (Dragon Skin 30: 0.59 MPa; Ecoflex 00-30: '
        '0.069 MPa; Sylgard 184: 1.3-3.0 MPa)', low=1e3, high=1e9),
    'gripper.finger.solid_pad.poisson_ratio': Key(0.45, '', 'solid_pad: Poisson ratio nu '
                                                  '(silicone rubbers are nearly '
                                                  'incompressible, ~0.49; 0.45 keeps the '
                                                  'linear triangles from locking)', low=0.0,
                                                  high=0.49),
    'gripper.finger.solid_pad.density': Key(1080.0, 'kg/m^3', 'solid_pad: density (Dragon '
                                            'Skin 30: 1080)', low=10.0, high=5000.0),
    'gripper.finger.solid_pad.layers': Key(4, '-', 'solid_pad: mesh cells across the '
                                           'thickness (the cells are about square)', 'int',
                                           1, 32),
    # --- contact
    'contact.model': Key('mmm', '-', 'contact with the rigid faces (jaws, table, walls): mmm '
                         '= the modified mass method (held nodes prescribed on the faces); '
                         'ipc = a barrier energy (Incremental Potential Contact, through '
                         'ipctk; 2D and 3D, no soft pads, no restitution, the generic solver)', 'str',
                         choices=('mmm', 'ipc')),
    'contact.ipc.dhat': Key(1e-6, 'm', 'ipc: barrier activation distance dhat (the largest '
                            'gap that still carries force; nodes stay within it of a face)',
                            low=1e-9, high=1e-3),
    'contact.ipc.stiffness': Key(0.1, 'N', 'ipc: barrier stiffness kappa (a node pressed with '
                                 'force F stays about 2 kappa dhat / F from the face)',
                                 low=1e-6, high=1e6),
    'contact.jaw.static_friction': Key(0.5, '', 'static friction coefficient '
                                       'fruit-jaw mu_s (rubber pad, estimate)',
                                       low=0.0, high=5.0, runtime=True),
    'contact.jaw.kinetic_friction': Key(0.4, '', 'kinetic friction coefficient '
                                        'fruit-jaw mu_k (<= mu_s)', low=0.0, high=5.0, runtime=True),
    'contact.table.static_friction': Key(0.5, '', 'static friction fruit-table',
                                         low=0.0, high=5.0, runtime=True),
    'contact.table.kinetic_friction': Key(0.4, '', 'kinetic friction fruit-table',
                                          low=0.0, high=5.0, runtime=True),
    'contact.pad.friction': Key(0.8, '', 'friction coefficient fruit-soft pad (smoothed '
                                'Coulomb, one coefficient; silicone 0.5-1.0, estimate)',
                                low=0.0, high=5.0),
    'contact.restitution': Key(0.0, '', 'normal restitution coefficient e of node '
                               'impacts on the table and walls', low=0.0, high=1.0, runtime=True),
    'contact.release_threshold': Key(1e-6, 'N', 'hysteresis: a contact is released '
                                     'only once its reaction pulls by more than this',
                                     low=0.0, high=1.0),
    'contact.max_correction_speed': Key(0.05, 'm/s', 'fastest rate at which an '
                                        'existing penetration is removed', low=1e-6,
                                        high=10.0),
    # --- world
    'world.gravity': Key(9.81, 'm/s^2', 'gravity, acting along -z', low=0.0, high=100.0),
    'world.table': Key(True, '-', 'a table (floor) at table_height', 'bool'),
    'world.table_height': Key(0.0, 'm', 'height of the table surface', low=-10.0,
                              high=10.0),
    'world.walls': Key(False, '-', 'two vertical walls at x = +/- wall_half_width',
                       'bool'),
    'world.wall_half_width': Key(0.5, 'm', 'wall position', low=1e-3, high=100.0),
    # --- the grasp window
    'window.max_slip': Key(1e-3, 'm', 'grasp window: a trial holds when the fruit slid '
                           'less than this in the jaws from the lift-off to the end of the '
                           'hold (the lower bound is the smallest force that does)',
                           low=0.0, high=0.01, open_low=True),
    # --- solver
    'sim.dt': Key(1e-3, 's', 'physics time step (3D default 20 ms: forces within 1-3 %, '
                  'contact areas and pressures within 1 % of a 5 ms step)', low=1e-7,
                  high=0.1, open_low=True, default_3d=0.02),
    'sim.newton_tolerance': Key(1e-6, 'm/s', 'Newton stops when the infinity norm of '
                                'the update divided by dt is below this', low=1e-14,
                                high=1.0, open_low=True),
    'sim.max_newton_iterations': Key(25, '-', 'Newton iterations before the step is '
                                     'halved; on the Newton solver (barrier contact, '
                                     'deformable fingers, 3D) a solve whose last 5 steps '
                                     'shrank by half or more goes on, up to 4 times as '
                                     'many', 'int', 1, 1000),
    'sim.max_halvings': Key(6, '-', 'times a failing step is halved before giving up',
                            'int', 0, 30),
    'sim.max_contact_passes': Key(10, '-', 'predictor-corrector passes per step',
                                  'int', 1, 50),
}

#: the keys that may change while a simulation runs (``Key.runtime``)
RUNTIME_KEYS = tuple(key for key, spec in SCHEMA.items() if spec.runtime)


class Parameters(dict):
    """A validated configuration: ``{'dotted.key': value}``, every value of its schema
    key's type and range. Frozen: it cannot be changed in place (a changed
    configuration is a new one, ``replaced``, validated again); ``dict(parameters)`` is
    a plain, editable copy. Built by ``validate`` (and so by ``load_config``).
    """

    __slots__ = ()

    def _frozen(self, *args, **kwargs):
        raise TypeError('a validated configuration is frozen: build a new one with '
                        'replaced({key: value}) or edit dict(config)')

    __setitem__ = __delitem__ = __ior__ = _frozen
    update = pop = popitem = clear = setdefault = _frozen

    def __reduce__(self):
        return Parameters._restore, (dict(self),)

    @staticmethod
    def _restore(values: dict) -> 'Parameters':
        parameters = Parameters()
        dict.update(parameters, values)
        return parameters

    def replaced(self, changes: Mapping[str, Any]) -> 'Parameters':
        """A new validated configuration with ``changes`` applied (ConfigError if one
        is unknown or out of range)."""
        return validate({**self, **changes})



def package_config_dir() -> Path:
    """Directory holding the YAML presets (``config/`` in the source tree or share/)."""
    here = Path(__file__).resolve().parent
    candidates = [here.parent / 'config', here / 'config']
    prefix = os.environ.get('AMENT_PREFIX_PATH', '')
    candidates += [Path(p) / 'share' / 'gripper_sim' / 'config' for p in prefix.split(':') if p]
    for candidate in candidates:
        if (candidate / 'fruits').is_dir():
            return candidate
    return candidates[0]


def available_fruits() -> list[str]:
    """Names of the fruit presets in ``config/fruits``."""
    return sorted(p.stem for p in (package_config_dir() / 'fruits').glob('*.yaml'))


@functools.cache
def fruit_property_keys() -> frozenset[str]:
    """The keys some fruit preset of ``config/fruits`` sets: a fruit's properties (its
    shape, flesh, skin, friction, ...), as against the modelling choices no preset makes
    (e.g. ``fruit.nodes``)."""
    return frozenset(key for name in available_fruits()
                     for key in flatten(read_yaml(fruit_preset_path(name))))


def defaults() -> dict:
    """The embedded defaults as a nested dict."""
    return unflatten({key: copy.deepcopy(spec.default) for key, spec in SCHEMA.items()})


def flatten(tree: Mapping, prefix: str = '', source: str = '') -> dict[str, Any]:
    """Nested mapping to ``{'a.b.c': value}``.

    Raises:
        ConfigError: a key given twice, dotted and nested (``sim.dt: 0.001`` beside
            ``sim: {dt: 0.002}``), naming it and ``source`` (e.g. "config file 'x.yaml'").
    """
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        dotted = f'{prefix}{key}'
        leaves = (flatten(value, dotted + '.', source) if isinstance(value, Mapping)
                  else {dotted: value})
        for name, leaf in leaves.items():
            if name in flat:
                where = f' in {source}' if source else ''
                raise ConfigError(f"key '{name}' is given twice{where} (once dotted, once "
                                  'nested): keep one')
            flat[name] = leaf
    return flat


def unflatten(flat: Mapping[str, Any]) -> dict:
    """``{'a.b.c': value}`` to a nested dict."""
    tree: dict = {}
    for dotted, value in flat.items():
        node = tree
        parts = dotted.split('.')
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return tree


def _coerce(key: str, value: Any) -> Any:
    spec = SCHEMA[key]
    if value is None:
        if spec.nullable:
            return None
        raise ConfigError(f"config key '{key}' must not be null ({spec.description})")
    try:
        if spec.kind == 'float':
            if isinstance(value, bool):
                raise ValueError
            number = float(value)
        elif spec.kind == 'int':
            if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                raise ValueError
            number = int(value)
        elif spec.kind == 'bool':
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in ('true', 'yes', 'on', '1'):
                return True
            if text in ('false', 'no', 'off', '0'):
                return False
            raise ValueError
        else:
            if isinstance(value, (list, tuple)):
                # a list (e.g. fruit.shape.points) is kept as its JSON text, so that every
                # value stays a scalar (a ROS parameter, a recording's config dump)
                text = json.dumps(value)
            else:
                text = str(value)
            if spec.choices and text not in spec.choices:
                raise ConfigError(f"config key '{key}' must be one of "
                                  f"{', '.join(spec.choices)}, got '{text}'")
            return text
    except (TypeError, ValueError) as err:
        raise ConfigError(f"config key '{key}' must be {KIND_NAMES[spec.kind]}, "
                          f"got {value!r}") from err
    if not math.isfinite(number):
        raise ConfigError(f"config key '{key}' must be finite, got {value!r}")
    unit = f' {spec.unit}' if spec.unit not in ('', '-') else ''
    if spec.low is not None and (number < spec.low or (spec.open_low and number <= spec.low)):
        relation = '>' if spec.open_low else '>='
        raise ConfigError(f"config key '{key}' = {number}{unit} is out of range: "
                          f'it must be {relation} {spec.low}{unit}')
    if spec.high is not None and number > spec.high:
        raise ConfigError(f"config key '{key}' = {number}{unit} is out of range: "
                          f'it must be <= {spec.high}{unit}')
    return number


def parse_override(text: str) -> tuple[str, Any]:
    """``'fruit.nodes=96'`` to ``('fruit.nodes', 96)`` (value parsed as YAML)."""
    if '=' not in text:
        raise ConfigError(f"override '{text}' must look like dotted.key=value")
    key, _, raw = text.partition('=')
    key = key.strip()
    if key not in SCHEMA and key not in SELECTORS:
        raise ConfigError(f"unknown config key '{key}'{key_suggestion(key)}")
    value = parse_yaml(raw, f"override '{text}': value") if raw.strip() else None
    if key in SELECTORS and not isinstance(value, str):
        raise ConfigError(f"override '{text}': {key} must be a {key} preset name")
    return key, value


def key_suggestion(key: str) -> str:
    """' (did you mean ...?)' naming the configuration key (or preset selector) closest
    to the unknown ``key``, or '' if none is close: the tail of an unknown-key error."""
    import difflib
    close = difflib.get_close_matches(key, list(SCHEMA) + list(SELECTORS), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ''


def read_yaml(path: str | os.PathLike) -> dict:
    """Read a YAML mapping (UTF-8 text), turning every failure into a ConfigError."""
    source = f"config file '{path}'"
    try:
        raw = Path(path).read_bytes()
    except OSError as err:
        raise ConfigError(f"cannot read {source}: {err.strerror}") from err
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError as err:
        raise ConfigError(f'{source} is not UTF-8 text (byte 0x{raw[err.start]:02x} at '
                          f'offset {err.start}): save it as UTF-8') from None
    data = parse_yaml(text, source)
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source} must hold a mapping of keys")
    return dict(data)


class UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader refusing a mapping key given twice (``SafeLoader`` keeps the
    last one silently); a merge (``<<: *base``) may still be overridden."""

    def construct_mapping(self, node, deep=False):
        first_marks: dict = {}
        for key_node, _ in node.value:
            if key_node.tag == 'tag:yaml.org,2002:merge':
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                first = first_marks.setdefault(key, key_node.start_mark)
            except TypeError:   # an unhashable key: the base class says so
                continue
            if first is not key_node.start_mark:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key '{key}' is given twice (first on line "
                    f'{first.line + 1}): keep one', key_node.start_mark)
        return super().construct_mapping(node, deep)


def parse_yaml(text: str, source: str) -> Any:
    """The YAML document ``text`` (``UniqueKeyLoader``); ConfigError with a one-line
    reason (line and column of the problem) naming ``source``."""
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a safe loader
    except yaml.YAMLError as err:
        raise ConfigError(f'{source} is not valid YAML: {yaml_problem(err)}') from None
    except RecursionError:
        raise ConfigError(f'{source} is not valid YAML: it nests too deeply') from None


def yaml_problem(err: yaml.YAMLError) -> str:
    """A PyYAML error on one line: where (line, column) and what."""
    mark = getattr(err, 'problem_mark', None)
    if isinstance(err, yaml.MarkedYAMLError) and mark is not None:
        context = ''
        if err.context and err.context_mark is not None:
            context = (f' ({err.context} from line {err.context_mark.line + 1}, column '
                       f'{err.context_mark.column + 1})')
        return f'line {mark.line + 1}, column {mark.column + 1}: {err.problem}{context}'
    if isinstance(err, yaml.reader.ReaderError):   # (``character``: the code point)
        return (f'character #x{err.character:04x} at offset {err.position} is not '
                f'allowed ({err.reason})')
    return ' '.join(str(err).split())


def available_fingers() -> list[str]:
    """Names of the finger presets in ``config/fingers``."""
    return sorted(p.stem for p in (package_config_dir() / 'fingers').glob('*.yaml'))


def finger_preset_path(name: str) -> Path:
    """Path of the preset for finger ``name``; ConfigError if there is none."""
    path = package_config_dir() / 'fingers' / f'{name}.yaml'
    if not path.is_file():
        known = ', '.join(available_fingers()) or 'none installed'
        raise ConfigError(f"unknown finger '{name}' (known fingers: {known})")
    return path


def is_preset_file(name: str) -> bool:
    """Whether a fruit name is a path to a preset file (``*.yaml``/``*.yml``, e.g. one
    written by ``gripper-sim calibrate``) rather than the name of a built-in preset."""
    return name.endswith(PRESET_SUFFIXES)


def fruit_preset_path(name: str, base_dir: str | os.PathLike | None = None) -> Path:
    """Path of the preset for fruit ``name``; ConfigError if there is none.

    A ``name`` ending in .yaml/.yml is a preset file: relative to the working directory,
    else to ``base_dir`` (the directory of the configuration file that names it).
    """
    if is_preset_file(name):
        path = Path(name).expanduser()
        if not path.is_file() and base_dir is not None and not path.is_absolute():
            path = Path(base_dir) / path
        if not path.is_file():
            raise ConfigError(f"fruit preset file '{name}' not found")
        return path
    path = package_config_dir() / 'fruits' / f'{name}.yaml'
    if not path.is_file():
        known = ', '.join(available_fruits()) or 'none installed'
        raise ConfigError(f"unknown fruit '{name}' (known fruits: {known})")
    return path


def validate(flat: Mapping[str, Any]) -> Parameters:
    """Check every key is known and in range; returns the coerced flat mapping, frozen
    (a ``Parameters`` is returned as it is: it was validated when it was built)."""
    if isinstance(flat, Parameters):
        return flat
    result: dict[str, Any] = {}
    for key, value in flat.items():
        if key not in SCHEMA:
            raise ConfigError(f"unknown config key '{key}'{key_suggestion(key)}")
        result[key] = _coerce(key, value)
    if result['contact.jaw.kinetic_friction'] > result['contact.jaw.static_friction']:
        raise ConfigError("config key 'contact.jaw.kinetic_friction' must not exceed "
                          "'contact.jaw.static_friction'")
    if result['contact.table.kinetic_friction'] > result['contact.table.static_friction']:
        raise ConfigError("config key 'contact.table.kinetic_friction' must not exceed "
                          "'contact.table.static_friction'")
    _check_shape(result)
    if result.get('gripper.finger.type') == 'arc':
        check_finger(result)
    check_fin_ray(result)
    check_solid_pad(result)
    return Parameters._restore(result)


def _check_shape(config: Mapping[str, Any]) -> None:
    """The outline can be built (no self-crossing, ...) and suits the fruit model."""
    kind = config.get('fruit.shape.type', 'circle')
    if kind == 'circle':
        return
    outline_from_config(config)
    if config.get('fruit.model') == 'shell' and config.get('fruit.pressure.turgor', 0) > 0:
        raise ConfigError(f"config key 'fruit.shape.type' = {kind}: the shell model holds "
                          'only a circular outline under turgor (a pressurised membrane '
                          "is round); use 'fruit.model' = solid for this shape, or set "
                          "'fruit.pressure.turgor' = 0")


def load_config(fruit: str | None = None, config_file: str | os.PathLike | None = None,
                overrides: Iterable[str] | Mapping[str, Any] = (),
                finger: str | None = None, fallback_fruit: str | None = None,
                fallback_finger: str | None = None) -> Parameters:
    """Build a validated flat configuration ``{'dotted.key': value}``.

    Precedence: the schema's defaults (its 3D defaults when ``dimension`` is 3) < the
    fruit preset < the finger preset < the file < the overrides. There is always a fruit
    preset: a file layers over one. It is, first found: ``--set fruit=NAME`` (an
    override ``fruit``), ``fruit``, the file's top-level ``fruit: NAME``,
    ``fallback_fruit`` (a scenario's), the default fruit (``DEFAULT_FRUIT``). A choice
    that replaces another given one (not a fallback) is a ``ConfigWarning``. The finger
    preset likewise.

    Args:
        fruit: preset name in ``config/fruits``, or the path of a preset file
            (``*.yaml``, e.g. written by ``gripper-sim calibrate``).
        config_file: a YAML file of keys (nested or dotted), merged after the presets;
            its top-level ``fruit: NAME`` / ``finger: NAME`` select presets.
        overrides: ``['key=value', ...]`` strings or a ``{key: value}`` mapping,
            applied last; the keys ``fruit`` and ``finger`` select presets.
        finger: preset name in ``config/fingers`` (``gripper.finger.*`` keys), merged
            after the fruit preset.
        fallback_fruit, fallback_finger: presets used when nothing else chooses one.

    Raises:
        ConfigError: unknown fruit, finger or key, bad YAML, value out of range.
    """
    data: dict[str, Any] = {}
    if config_file is not None:
        data = read_yaml(config_file)
        _drop_provenance(data, f"config file '{config_file}'")
    if isinstance(overrides, Mapping):
        items = list(overrides.items())
    else:
        items = [parse_override(text) for text in overrides]
    choices = {selector: [] for selector in SELECTORS}   # (source, name), strongest first
    for key, value in reversed(items):
        if key in SELECTORS:
            choices[key].append((f'--set {key}={value}', value))
    for selector, given in (('fruit', fruit), ('finger', finger)):
        if given is not None:
            choices[selector].append((f'--{selector} {given}', given))
        if isinstance(data.get(selector), str):
            choices[selector].append((f"the config file's '{selector}: {data[selector]}'",
                                      data.pop(selector)))
    for selector, fallback in (('fruit', fallback_fruit), ('finger', fallback_finger)):
        if fallback is not None and not choices[selector]:   # a default, replaced quietly
            choices[selector].append((f"the scenario's '{selector}: {fallback}'", fallback))
    fruit_name = _chosen('fruit', choices['fruit']) or DEFAULT_FRUIT
    finger_name = _chosen('finger', choices['finger'])
    base_dir = Path(config_file).parent if config_file is not None else None
    preset_keys, provenance = _preset(fruit_name, base_dir)
    chosen: dict[str, Any] = dict(preset_keys)
    if finger_name is not None:
        chosen.update(_finger_preset(finger_name))
    user: dict[str, Any] = {}
    if config_file is not None:
        user.update(_checked_flatten(data, f"config file '{config_file}'"))
    for key, value in items:
        if key in SELECTORS:
            continue
        if key not in SCHEMA:
            raise ConfigError(f"unknown config key '{key}'{key_suggestion(key)}")
        user[key] = value
    presets = dict(chosen)
    chosen.update(user)
    flat = flatten(defaults())
    if _coerce('dimension', chosen.get('dimension', flat['dimension'])) == 3:
        flat.update({key: spec.default_3d for key, spec in SCHEMA.items()
                     if spec.default_3d is not None})
    baseline = {**flat, **presets}
    flat.update(chosen)
    if ('gripper.finger.type' in user and 'gripper.finger.name' not in user
            and flat['gripper.finger.type'] != baseline['gripper.finger.type']):
        # the outputs name the finger: a type chosen by key, not by preset, is its name
        flat['gripper.finger.name'] = flat['gripper.finger.type']
    config = validate(flat)
    # a key restated at the value it has anyway (a saved or recorded full configuration
    # loaded again) is no choice of the user's: only changed keys are warned about
    changed = {key: value for key, value in user.items()
               if key not in baseline or config[key] != _coerce(key, baseline[key])}
    for message in no_effect_warnings(config, changed, fruit_name):
        warnings.warn(message, ConfigWarning, stacklevel=2)
    for warning in (calibration_warning(fruit_name, provenance, config['dimension']),
                    fin_ray_resolution_warning(config)):
        if warning:
            warnings.warn(warning, ConfigWarning, stacklevel=2)
    return config


def _chosen(selector: str, choices: list[tuple[str, str]]) -> str | None:
    """The strongest of the preset ``choices`` ((source, name), strongest first); a
    ``ConfigWarning`` for each other one it replaces."""
    if not choices:
        return None
    source, name = choices[0]
    for other, replaced in choices[1:]:
        if replaced != name:
            warnings.warn(f"{source} replaces {other}: the {selector} preset is '{name}'",
                          ConfigWarning, stacklevel=3)
    return name


#: the keys that have no effect in some set-ups (``no_effect_reason``)
PAD_KEYS = ('contact.pad.friction', 'gripper.finger.pad.thickness',
            'gripper.finger.pad.youngs_modulus', 'gripper.finger.pad.poisson_ratio')
JAW_FRICTION_KEYS = ('contact.jaw.static_friction', 'contact.jaw.kinetic_friction')


def no_effect_reason(key: str, config: Mapping[str, Any]) -> str | None:
    """Why ``key`` has no effect in ``config``'s set-up, naming what does; None if it has."""
    pad = config['gripper.finger.pad.enabled']
    finger = config['gripper.finger.type']
    if key in PAD_KEYS and finger not in RIGID_FINGERS:
        return f'the {finger} finger is itself soft: a pad layer on it is not modelled'
    if key in JAW_FRICTION_KEYS and pad:
        return ("a soft pad covers the jaws ('gripper.finger.pad.enabled'): the friction "
                "there is 'contact.pad.friction'")
    if key == 'contact.pad.friction' and not pad:
        return ("there is no pad ('gripper.finger.pad.enabled' is false): the jaw "
                "friction is 'contact.jaw.static_friction' and 'contact.jaw.kinetic_friction'")
    if key in PAD_KEYS and not pad:
        return "there is no pad: set 'gripper.finger.pad.enabled' = true"
    if key in ('gripper.finger.radius', 'gripper.finger.segments') and finger != 'arc':
        return f"the finger is {finger}, not an arc: set 'gripper.finger.type' = arc"
    if key == 'gripper.finger.groove_angle' and finger != 'vgroove':
        return f"the finger is {finger}, not a V-groove: set 'gripper.finger.type' = vgroove"
    if key.startswith('gripper.finger.fin_ray.') and finger != 'fin_ray':
        return f"the finger is {finger}, not a Fin Ray: set 'gripper.finger.type' = fin_ray"
    if (key in ('gripper.finger.fin_ray.rib_count', 'gripper.finger.fin_ray.rib_angle')
            and config['gripper.finger.fin_ray.rib_ends'] is not None):
        return "'gripper.finger.fin_ray.rib_ends' places the ribs"
    if key == 'gripper.finger.fin_ray.contact_dhat' and config['dimension'] != 3:
        return "in 2D the Fin Ray's fruit contact is 'contact.ipc.dhat'"
    if key == 'gripper.finger.fin_ray.section' and config['dimension'] == 3:
        return "in 3D the Fin Ray's members are shells: they bend as plates"
    if (key in ('gripper.finger.fin_ray.youngs_modulus', 'gripper.finger.fin_ray.density',
                'gripper.finger.fin_ray.poisson_ratio')
            and config['gripper.finger.fin_ray.material'] != 'custom'):
        return ("the Fin Ray's material is "
                f"{config['gripper.finger.fin_ray.material']}: set "
                "'gripper.finger.fin_ray.material' = custom")
    if key.startswith('gripper.finger.solid_pad.') and finger != 'solid_pad':
        return f"the finger is {finger}, not a solid pad: set 'gripper.finger.type' = solid_pad"
    if (key.startswith('contact.ipc.') and finger in RIGID_FINGERS
            and config['contact.model'] == 'mmm'):
        return ("the contact with the rigid fingers is the modified mass method: the "
                "barrier's keys apply with 'contact.model' = ipc or a deformable finger")
    if key == 'contact.model' and finger not in RIGID_FINGERS:
        return (f'the finger is the deformable {finger}: every contact is the barrier '
                "(the 'contact.ipc.*' keys)")
    model = config['fruit.model']
    if key in ('fruit.pressure.turgor', 'fruit.pressure.bulk_modulus') and model != 'shell':
        return f"only the shell model has an internal pressure ('fruit.model' is {model})"
    return None


def no_effect_warnings(config: Mapping[str, Any], user: Mapping[str, Any],
                       fruit_preset: str | None = None) -> list[str]:
    """One line per key the user set (``user``: from a file or an override) that has no
    effect in ``config``'s set-up, naming the key that does; and a ``fruit.name`` that
    names another fruit preset than the one loaded (``fruit_preset``): it only renames."""
    lines = []
    for key in user:
        reason = no_effect_reason(key, config)
        if reason is not None:
            lines.append(f"config key '{key}' has no effect: {reason}")
    name = user.get('fruit.name')
    if (fruit_preset is not None and isinstance(name, str) and name != fruit_preset
            and name in available_fruits()):
        lines.append(f"config key 'fruit.name' = {name} only renames the '{fruit_preset}' "
                     f"preset (its physics stay); to load the {name} preset use "
                     f"--fruit {name} or --set fruit={name}")
    return lines


def _preset(name: str, base_dir: Path | None = None) -> tuple[dict[str, Any], Mapping]:
    """The fruit preset's flat keys and its ``calibration:`` record ({} if none)."""
    data = read_yaml(fruit_preset_path(name, base_dir))
    provenance: Mapping = {}
    if is_preset_file(name):
        provenance = _drop_provenance(data, f"fruit preset file '{name}'")
    return _checked_flatten(data, f'fruit preset {name}'), provenance


def _drop_provenance(data: dict, source: str) -> Mapping:
    """Remove the ``calibration:`` record (where a preset came from) from ``data``;
    returns it ({} if none)."""
    provenance = data.pop(PROVENANCE_KEY, None)
    if provenance is not None and not isinstance(provenance, Mapping):
        raise ConfigError(f"{source}: '{PROVENANCE_KEY}' must be a mapping")
    return provenance or {}


def calibration_warning(fruit: str, provenance: Mapping, dimension: int) -> str | None:
    """A warning when a calibrated preset runs in another dimension than it was fitted
    in (its flesh or turgor were fitted for that model), else None."""
    fitted = provenance.get('dimension')
    if fitted is None or int(fitted) == int(dimension):
        return None
    return (f"fruit preset file '{fruit}' was calibrated in {int(fitted)}D "
            f"({provenance.get('model', 'its')} model); this run is {int(dimension)}D, "
            f"where its fitted values need not fit the data: add --set "
            f"dimension={int(fitted)} to run it as calibrated")


def _finger_preset(name: str) -> dict[str, Any]:
    return _checked_flatten(read_yaml(finger_preset_path(name)), f'finger preset {name}')


def _checked_flatten(data: Mapping, source: str) -> dict[str, Any]:
    flat = flatten(data, source=source)
    for key in flat:
        if key not in SCHEMA:
            raise ConfigError(f"unknown config key '{key}' in {source}{key_suggestion(key)}")
    return flat


def to_yaml(flat: Mapping[str, Any]) -> str:
    """A flat configuration as nested YAML text (for recording and reproducing runs)."""
    return yaml.safe_dump(unflatten(dict(flat)), sort_keys=True)
