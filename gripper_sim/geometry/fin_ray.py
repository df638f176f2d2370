"""The Fin Ray finger's plane geometry: beams, ribs and their discretisation into rods.

Finger frame (as ``gripper_sim.core.finger_body``): x (m) from the jaw's backing (x = 0)
towards the fruit, z (m) up, z = 0 at the jaw's centre height. The finger is a triangle
of height ``length``: its base, ``base_width`` long along x, is on the jaw at the top
(z = +length / 2, from x = 0 to x = base_width); the back beam runs down from the
backing to the tip (x = ``tip_offset``, z = -length / 2); the front beam, the side that
touches the fruit, runs from the base's front corner (base_width, +length / 2) down to
the tip: two flexible bands meeting at the tip, joined by ribs (as Festo's gripper
finger DHAS: polyurethane bands joined by intermediate bridges). With ``tip_offset`` 0
the two fingers open into a V towards their tips; near ``base_width`` their front beams
are nearly parallel to the jaws.

``rib_count`` ribs start on the back beam at equal spacing in height between base and
tip and run to the front beam at ``rib_angle`` to the base (0: parallel to the base;
positive: their front ends lower, towards the tip); or, with ``rib_ends`` given, each rib
joins the two beams at the given distances from the base along each beam (a published
finger's crossbeams). Where a rib meets a beam the joint is rigid, or with ``rib_joint``
'pinned' a hinge (the rib a two-force link). Every member (base, back beam, front
beam, each rib) is a chain of rod elements about ``element_length`` long along its
centre line, with nodes where members meet.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gripper_sim.errors import ConfigError
from gripper_sim.geometry.shapes import outline_from_config, parse_points

PREFIX = 'gripper.finger.fin_ray.'
#: nodes a finger's section may have at most (its member lengths over element_length,
#: about; the default finger has 104, the 3D finger each node in every slice): finer,
#: and the matrices of its contact pairs outgrow any memory
MAX_SECTION_NODES = 1000
#: the longest element (in fruit outline node spacings) that keeps a jaw's contact one
#: patch (docs/fin_ray_convergence.md: 1.3 does, 1.9 does not)
COARSEST_ELEMENT = 1.5
#: m, a null ``element_length`` in 2D: the first of these no longer than
#: ``COARSEST_ELEMENT`` outline spacings (the last if none is): 4 mm gives the 1 mm
#: finger's grasp figures within about 2 % on the default apple, in about 70 % of the
#: 2 mm finger's CPU time (docs/fin_ray_convergence.md)
FOLLOWED_ELEMENTS = (0.004, 0.002, 0.001, 0.0005)
#: m, a null ``element_length`` in 3D: its slices across the width scale with it too
#: (``core3d.soft_fingers3d.WIDTH_CELL_RATIO``), and the 3D figures were measured at it
ELEMENT_3D = 0.002
#: the longest element, as a fraction of the finger's length
LONGEST_ELEMENT = 0.25
#: how a rib joins the beams: welded (rest angle kept) or hinged
RIB_JOINTS = ('rigid', 'pinned')


@dataclass(frozen=True)
class FinRayGeometry:
    """Attributes (m unless noted):
        length: height of the finger along z.
        base_width: width of its base along x (the front beam's distance from the
            backing at the base).
        depth: out-of-plane depth (along the jaw); None: not chosen yet (the fruit's,
            which the physics knows; the plane geometry and its checks do not need it).
        beam_thickness: of the front and back beams.
        rib_thickness: of each rib.
        rib_count: number of ribs (0: the rib-free frame of two beams).
        rib_angle: deg, of the ribs to the base (positive: front end towards the tip).
        element_length: rod element length of the discretisation.
        tip_offset: x of the tip (0: the back beam runs along the backing; near
            base_width: the front beam nearly parallel to the jaw).
        rib_angle_given: False when rib_angle was null in the configuration (then
            perpendicular to the back beam).
        rib_ends: None (the rule of rib_count and rib_angle), or per rib (distance along
            the back beam, distance along the front beam), m from the base (each beam's
            end on the base), top to bottom; it then sets the rib count.
        rib_joint: 'rigid' (a rib welded to the beams: the joint keeps its rest angle) or
            'pinned' (hinged: no moment between rib and beam).
    """

    length: float
    base_width: float
    depth: float | None
    beam_thickness: float
    rib_thickness: float
    rib_count: int
    rib_angle: float
    element_length: float
    tip_offset: float
    rib_angle_given: bool = True
    rib_ends: tuple[tuple[float, float], ...] | None = None
    rib_joint: str = 'rigid'

    @classmethod
    def from_config(cls, config, fruit_depth: float | None = None) -> 'FinRayGeometry':
        """From the ``gripper.finger.fin_ray.*`` keys of a flat configuration; a null
        depth is ``fruit_depth`` (m)."""
        values = {name: config[PREFIX + name] for name in cls.__dataclass_fields__
                  if name != 'rib_angle_given'}
        values['element_length'] = element_length(config)
        values['rib_ends'] = parse_rib_ends(values['rib_ends'])
        if values['rib_ends'] is not None:
            values['rib_count'] = len(values['rib_ends'])
            values['rib_angle'] = values['rib_angle'] or 0.0
        if values['depth'] is None:
            values['depth'] = fruit_depth
        values['rib_angle_given'] = values['rib_angle'] is not None
        if not values['rib_angle_given']:   # perpendicular to the back beam
            values['rib_angle'] = -math.degrees(math.atan2(values['tip_offset'],
                                                           values['length']))
        return cls(**values)


@dataclass(frozen=True)
class Member:
    """A chain of rod elements. Attributes: name ('base', 'back', 'front', 'rib0', ...);
    nodes (k,) in order along it; thickness (m); rigid: part of the jaw (the base)."""

    name: str
    nodes: np.ndarray
    thickness: float
    rigid: bool = False


@dataclass(frozen=True)
class FinRayLayout:
    """Attributes:
        positions: (m, 2) m, nodes in the finger frame.
        members: the chains (base first, then back and front beams, then the ribs).
        base_nodes: (k,) the nodes of the base (on the jaw).
        front_nodes: (f,) the front beam's nodes from the tip up to the base.
        tip_node: where the beams meet.
        rib_ends: (rib_count, 2) m, each rib's front end on the front beam.
    """

    positions: np.ndarray
    members: list[Member]
    base_nodes: np.ndarray
    front_nodes: np.ndarray
    tip_node: int
    rib_ends: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


def _error(name: str, value, reason: str) -> ConfigError:
    return ConfigError(f"config key '{PREFIX}{name}' = {value:g}: {reason}")


def parse_rib_ends(value) -> tuple[tuple[float, float], ...] | None:
    """The ``rib_ends`` key (a list of [back, front] pairs, m, or its JSON/YAML text;
    None or '' for none) as a tuple of pairs; ConfigError if it is not such a list."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    pairs = parse_points(value, PREFIX + 'rib_ends', pair='[back, front]', outline=False)
    return tuple((float(b), float(f)) for b, f in pairs)


def _beams(g: FinRayGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(back corner, back beam unit vector, front corner, front beam unit vector), each
    (2,), the beams' directions from the base towards the tip."""
    half = 0.5 * g.length
    back_corner = np.array([0.0, half])
    front_corner = np.array([g.base_width, half])
    tip = np.array([g.tip_offset, -half])
    return (back_corner, (tip - back_corner) / np.linalg.norm(tip - back_corner),
            front_corner, (tip - front_corner) / np.linalg.norm(tip - front_corner))


def _given_rib_points(g: FinRayGeometry) -> tuple[np.ndarray, np.ndarray]:
    """``rib_points`` of explicit ``rib_ends``, checked: each end on its beam (at least
    a thickness from the base and the tip), the ribs in the same order along both
    beams (else they cross) and their ends more than a rib thickness apart."""
    ends = np.array(g.rib_ends, dtype=float).reshape(-1, 2)
    back_corner, back_dir, front_corner, front_dir = _beams(g)
    lengths = (math.hypot(g.tip_offset, g.length),
               math.hypot(g.base_width - g.tip_offset, g.length))
    margin = max(g.beam_thickness, g.rib_thickness)
    key = f"config key '{PREFIX}rib_ends'"
    for k, pair in enumerate(ends):
        for value, beam, length in zip(pair, ('back', 'front'), lengths):
            if not (math.isfinite(value) and margin <= value <= length - margin):
                raise ConfigError(
                    f'{key}: rib {k + 1} of {len(ends)} is off the {beam} beam: its end '
                    f'at {value * 1e3:.4g} mm from the base must lie from {margin * 1e3:.3g} '
                    f'to {(length - margin) * 1e3:.4g} mm (the {beam} beam is '
                    f'{length * 1e3:.4g} mm long)')
    order = np.argsort(ends[:, 0], kind='stable')
    ends = ends[order]
    for k in range(len(ends) - 1):
        step = ends[k + 1] - ends[k]
        if step[0] <= g.rib_thickness or step[1] <= g.rib_thickness:
            which = ('cross: the ribs must come in the same order along both beams'
                     if step[1] < 0 else
                     f'are not more than a rib thickness ({g.rib_thickness * 1e3:.3g} mm) '
                     'apart')
            raise ConfigError(
                f'{key}: ribs {order[k] + 1} and {order[k + 1] + 1} {which}: back ends '
                f'{ends[k, 0] * 1e3:.4g} and {ends[k + 1, 0] * 1e3:.4g} mm, front ends '
                f'{ends[k, 1] * 1e3:.4g} and {ends[k + 1, 1] * 1e3:.4g} mm from the base')
    return (back_corner + ends[:, :1] * back_dir, front_corner + ends[:, 1:] * front_dir)


def rib_points(geometry: FinRayGeometry) -> tuple[np.ndarray, np.ndarray]:
    """((n, 2), (n, 2)) m: each rib's back end on the back beam and front end on the
    front beam, top to bottom: from ``rib_ends`` if given, else ``rib_count`` ribs at
    equal height spacing on the back beam and ``rib_angle``.

    Raises:
        ConfigError: a rib that leaves the finger (its front end beyond the tip or above
            the base; a given end off its beam) or ribs that intersect (closer than a rib
            thickness; given ends in another order along the two beams).
    """
    g = geometry
    if g.rib_ends is not None:
        return _given_rib_points(g)
    n = int(g.rib_count)
    half = 0.5 * g.length
    spacing = g.length / (n + 1)
    heights = spacing * np.arange(1, n + 1)
    back = np.stack([g.tip_offset * heights / g.length, half - heights], axis=1)
    angle = math.radians(g.rib_angle)
    direction = np.array([math.cos(angle), -math.sin(angle)])
    corner = np.array([g.base_width, half])
    along = np.array([g.tip_offset, -half]) - corner          # front beam, base corner -> tip
    beam_length = float(np.hypot(*along))
    step = back[1] - back[0] if n > 1 else np.zeros(2)
    gap = abs(direction[0] * step[1] - direction[1] * step[0])   # between parallel ribs
    if n > 1 and gap <= g.rib_thickness:
        raise _error('rib_count', n, f'the ribs intersect: {n} ribs at {g.rib_angle:g} deg '
                     f'are {gap * 1e3:.3g} mm apart, not more than their thickness '
                     f'{g.rib_thickness * 1e3:.3g} mm')
    fronts = np.empty((n, 2))
    margin = max(g.beam_thickness, g.rib_thickness)
    crossing = np.stack([direction, -along], axis=1)
    derived = '' if g.rib_angle_given else (
        '; rib_angle is null, so perpendicular to the back beam: set it{}, or change '
        f'base_width ({g.base_width:g} m), tip_offset ({g.tip_offset:g} m) or rib_count')
    if n and abs(np.linalg.det(crossing)) <= 1e-12 * beam_length:
        raise _error('rib_angle', g.rib_angle, 'the ribs run parallel to the front beam: '
                     'they never meet it' + derived.format(''))
    for k in range(n):
        # back[k] + r direction = corner + s along
        r, s = np.linalg.solve(crossing, corner - back[k])
        if r <= 0 or not margin <= s * beam_length <= beam_length - margin:
            where = 'beyond the tip' if s > 0.5 else 'above the base'
            raise _error('rib_angle', g.rib_angle,
                         f'rib {k + 1} of {n} leaves the finger: its front end falls {where} '
                         f'(ribs start on the back beam {spacing * 1e3:.3g} mm apart)'
                         + derived.format(f" (a {'larger' if s <= 0.5 else 'smaller'} "
                                          'angle)'))
        fronts[k] = corner + s * along
    return back, fronts


def check_fin_ray(config) -> None:
    """ConfigError naming the key if the Fin Ray of a flat configuration cannot be built
    (only when ``gripper.finger.type`` is fin_ray). Whether two fingers fit the jaws'
    stroke with the fruit between them is the simulation's check (it knows the fruit's
    width and the open gap)."""
    if config.get('gripper.finger.type') != 'fin_ray':
        return
    if (config[PREFIX + 'material'] == 'custom'
            and config.get(PREFIX + 'youngs_modulus') is None):
        raise ConfigError(f"config key '{PREFIX}youngs_modulus' must be set for the custom "
                          'material')
    geometry = FinRayGeometry.from_config(config)
    check_geometry(geometry)


def outline_spacing(config) -> float:
    """m, the median distance between neighbouring nodes of the 2D fruit outline of a
    flat configuration."""
    outline = outline_from_config(config)
    return float(np.median(np.linalg.norm(np.roll(outline, -1, axis=0) - outline, axis=1)))


def element_length(config, spacing: float | None = None) -> float:
    """m, the Fin Ray's rod element length of a flat configuration: the key's value, or
    where it is null the fruit's (``FOLLOWED_ELEMENTS`` in 2D, no longer than
    ``LONGEST_ELEMENT`` of the finger's length either; ``ELEMENT_3D`` in 3D); ``spacing``
    (m) the fruit's ``outline_spacing`` if already known."""
    value = config[PREFIX + 'element_length']
    if value is not None:
        return float(value)
    if config.get('dimension') == 3:
        return ELEMENT_3D
    if spacing is None:
        spacing = outline_spacing(config)
    longest = COARSEST_ELEMENT * spacing
    finger = config[PREFIX + 'length']
    if math.isfinite(finger) and finger > 0:   # as ``check_geometry`` allows
        longest = min(longest, LONGEST_ELEMENT * finger)
    return next((length for length in FOLLOWED_ELEMENTS if length <= longest),
                FOLLOWED_ELEMENTS[-1])


def resolution_warning(config) -> str | None:
    """A line saying that the 2D Fin Ray of a flat configuration is too coarse for its
    fruit, or None. Elements longer than ``COARSEST_ELEMENT`` times the fruit outline's
    node spacing touch the fruit at separate nodes: each jaw's contact breaks into
    patches and the damage estimate, which takes each patch as a contact of its own,
    overstates the pressure (docs/fin_ray_convergence.md: 112 kPa instead of 67 at
    2.6 times, the apple's outline of 256 nodes)."""
    if config.get('gripper.finger.type') != 'fin_ray' or config.get('dimension') != 2:
        return None
    spacing = outline_spacing(config)
    element = element_length(config, spacing)
    if element <= COARSEST_ELEMENT * spacing:
        return None
    given = 'null: ' if config[PREFIX + 'element_length'] is None else ''
    return (f"config key '{PREFIX}element_length' = {given}{element * 1e3:.3g} mm is "
            f"{element / spacing:.2g} times the fruit outline's node spacing "
            f"({spacing * 1e3:.3g} mm, fruit.nodes = {config['fruit.nodes']}): the fruit "
            "touches the finger at separate nodes, each jaw's contact breaks into patches "
            "and the bruise estimate overstates the contact pressure; set it to at most "
            f"{COARSEST_ELEMENT * spacing * 1e3:.3g} mm")


def check_geometry(geometry: FinRayGeometry) -> None:
    """ConfigError naming the key for a geometry that cannot be built."""
    g = geometry
    for name in ('length', 'base_width', 'depth', 'beam_thickness', 'rib_thickness',
                 'element_length'):
        value = getattr(g, name)
        if name == 'depth' and value is None:
            continue
        if not (math.isfinite(value) and value > 0):
            raise _error(name, value, 'must be positive')
    if g.rib_count < 0:
        raise _error('rib_count', g.rib_count, 'must not be negative')
    if g.rib_joint not in RIB_JOINTS:
        raise ConfigError(f"config key '{PREFIX}rib_joint' must be one of "
                          f"{', '.join(RIB_JOINTS)}, got '{g.rib_joint}'")
    if g.beam_thickness >= 0.5 * g.base_width:
        raise _error('beam_thickness', g.beam_thickness,
                     f'the beams fill the base ({g.base_width:g} m wide): it must be below '
                     'half the base width')
    front_most = g.base_width - 2 * g.beam_thickness
    if not 0.0 <= g.tip_offset <= front_most:
        raise _error('tip_offset', g.tip_offset,
                     'the tip must lie between the backing and the front corner: 0 to '
                     f'base_width - 2 beam_thickness ({front_most:g} m)')
    if g.element_length > LONGEST_ELEMENT * g.length:
        raise _error('element_length', g.element_length,
                     f'too coarse: at most a quarter of the length ({g.length:g} m)')
    backs, fronts = rib_points(g)
    members = (g.base_width + math.hypot(g.tip_offset, g.length)
               + math.hypot(g.base_width - g.tip_offset, g.length)
               + float(np.hypot(*(fronts - backs).T).sum()))
    if members / g.element_length > MAX_SECTION_NODES:
        raise _error('element_length', g.element_length,
                     f'too fine: the members ({1e3 * members:.0f} mm in all) would have about '
                     f'{members / g.element_length:.3g} nodes, at most {MAX_SECTION_NODES}: '
                     f'use {math.ceil(1e5 * members / MAX_SECTION_NODES) / 1e5:g} m or more')


def layout(geometry: FinRayGeometry) -> FinRayLayout:
    """The nodes and member chains of a checked geometry (``check_geometry``)."""
    g = geometry
    half = 0.5 * g.length
    backs, fronts = (rib_points(g) if g.rib_count or g.rib_ends
                     else (np.zeros((0, 2)), np.zeros((0, 2))))
    positions: list[np.ndarray] = []

    def node(point) -> int:
        positions.append(np.asarray(point, dtype=float))
        return len(positions) - 1

    def chain(ends: list[int]) -> np.ndarray:
        """Nodes along the polyline through the existing nodes ``ends``, elements of
        about ``element_length``."""
        nodes = [ends[0]]
        for a, b in zip(ends[:-1], ends[1:]):
            pa, pb = positions[a], positions[b]
            count = max(1, math.ceil(float(np.hypot(*(pb - pa))) / g.element_length - 1e-9))
            nodes += [node(pa + (pb - pa) * i / count) for i in range(1, count)] + [b]
        return np.array(nodes, dtype=np.int64)

    back_corner = node([0.0, half])
    front_corner = node([g.base_width, half])
    tip = node([g.tip_offset, -half])
    back_joints = [node(p) for p in backs]
    front_joints = [node(p) for p in fronts]
    members = [Member('base', chain([back_corner, front_corner]), g.beam_thickness, True),
               Member('back', chain([back_corner, *back_joints, tip]), g.beam_thickness),
               Member('front', chain([tip, *front_joints[::-1], front_corner]),
                      g.beam_thickness)]
    members += [Member(f'rib{k}', chain([back_joints[k], front_joints[k]]), g.rib_thickness)
                for k in range(len(backs))]
    return FinRayLayout(np.array(positions), members, members[0].nodes, members[2].nodes,
                        tip, fronts)
