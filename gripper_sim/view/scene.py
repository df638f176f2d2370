"""The 3D scene of the live view: the node's markers as a Foxglove ``SceneUpdate``.

The node already draws its scene as a ``visualization_msgs/MarkerArray``
(``gripper_sim.convert.messages.markers``): the fruit coloured by contact pressure (2D
outline as a LINE_STRIP, 3D skin as a TRIANGLE_LIST with a colour per corner), the
jaws, shaped fingers and pads, the table, the jaw force arrows and the contact force
lines. Foxglove's 3D panel shows that array only through its ROS marker support;
this module turns it into Foxglove's own ``foxglove.SceneUpdate`` (one entity per
marker, id ``<ns>/<id>``) so that any Foxglove client shows it, live from the node
and the same from a recording (its ``markers`` topic). One change: the jaw force
arrows (ns ``jaw_forces``, ``ARROW_SCALE`` m per N in the markers: 1 m at the
200 N of ``gripper.max_force``) are drawn ``jaw_arrow_length`` long, 5 mm per N at
small forces and never as long as ``ARROW_CAP``, so that they stay clear of the labels
at any force; the grip force is written exactly in ``legend/state``. It adds two
entities:

- ``legend/pressure``: the colour scale of the fruit, a bar of ``LEGEND_STEPS``
  cubes coloured by ``pressure_colour`` from 0 to the bruise pressure, with labels
  (``0 kPa``, half and full bruise pressure, "contact pressure (damage estimate)").
- ``legend/state``: grip force, compression, slip and peak contact pressure of the
  step, from its ``FruitState``, one per line above the fruit.

Foxglove draws a text's ``font_size`` as its line height (m) in a monospace font, a
character about half as wide, and centres the text on its pose; it breaks lines at
``\\n``.

Pure functions of message objects (read by attribute, never imported from rclpy);
the Foxglove classes come from ``foxglove.messages``. Units: m, N, Pa; times in ns.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

from foxglove.messages import (ArrowPrimitive, Color, CubePrimitive, CylinderPrimitive,
                               LinePrimitive, LinePrimitiveLineType, Point3, Pose,
                               Quaternion, SceneEntity, SceneEntityDeletion,
                               SceneEntityDeletionType, SceneUpdate, SpherePrimitive,
                               TextPrimitive, Timestamp, TriangleListPrimitive, Vector3)

from gripper_sim.convert.messages import ARROW_SCALE, pressure_colour

# visualization_msgs/Marker type and action constants (fixed by its .msg definition).
ARROW, CUBE, SPHERE, CYLINDER, LINE_STRIP, LINE_LIST = 0, 1, 2, 3, 4, 5
TEXT_VIEW_FACING, TRIANGLE_LIST = 9, 11
ADD, DELETE, DELETEALL = 0, 2, 3   # MODIFY is ADD

LEGEND_STEPS = 10          # cubes in the colour bar
LEGEND_BAR_WIDTH = 0.25    # of its height, the colour bar's width (and depth)
LEGEND_TEXT_SIZE = 0.008   # m, line height of the legend labels
LEGEND_LABEL_OFFSET = 0.04   # m of room for the labels beside the bar (``beside``)
LEGEND_LABEL_GAP = 0.004   # m from the bar to the left end of its labels
STATE_TEXT_SIZE = 0.009    # m, line height of the state text
#: width of a character of Foxglove's (monospace) labels, in line heights
CHARACTER_WIDTH = 0.5
#: the colour bar's title, in two lines above the bar and its labels (one line,
#: centred on the bar, reached out of the layout's view)
LEGEND_TITLE = 'contact pressure\n(damage estimate)'
#: the marker namespace of the jaw force arrows (``convert.messages.markers``)
JAW_FORCE_NS = 'jaw_forces'
#: m, the length a jaw force arrow approaches at large forces and never reaches
#: (``jaw_arrow_length``); at ``ARROW_SCALE`` (5 mm per N) a force of 10-12 N ran the
#: apple's arrow into the colour bar's labels beside a lifted fruit (a strawberry's at
#: 5 N), and 200 N made it 1 m long
ARROW_CAP = 0.025
#: m, the least room between a jaw force arrow at ``ARROW_CAP`` and a label
ARROW_CLEARANCE = 0.01


def jaw_arrow_length(force: float) -> float:
    """m, the drawn length of a jaw force arrow of ``force`` (N, >= 0): ``ARROW_SCALE``
    per N at small forces, saturating towards ``ARROW_CAP``:
    cap F / (F + cap / ARROW_SCALE) (half the cap at 5 N, 80 % at 20 N, 97.6 % at
    200 N), longer for every larger force and shorter than the cap at any."""
    force = max(float(force), 0.0)
    return ARROW_CAP * force / (force + ARROW_CAP / ARROW_SCALE)


def text_extent(text: str, size: float) -> tuple[float, float]:
    """m, (width, height) of a label ``text`` of line height ``size`` as Foxglove
    draws it (``CHARACTER_WIDTH``; one line height per line)."""
    lines = text.split('\n')
    return CHARACTER_WIDTH * size * max(len(line) for line in lines), size * len(lines)


@dataclass(frozen=True)
class PressureLegend:
    """Where and for what scale the colour bar of the fruit is drawn (frame ``world``).

    Attributes:
        bruise_pressure: Pa, the top of the scale (red at and above it).
        x, y, z: m, the bottom of the bar.
        height: m, length of the bar (upwards).
        frame_id: the frame of the bar and of the state text.
    """

    bruise_pressure: float
    x: float
    y: float
    z: float
    height: float
    frame_id: str = 'world'

    @classmethod
    def beside(cls, context: Any) -> 'PressureLegend':
        """A legend beside the fruit for a ``MessageContext`` (its rest width, gripper
        centre, table height, bruise pressure and jaw plate) to the -x side: two fruit
        widths and the labels' room from the centre, and further out where its labels
        would reach the longest jaw force arrow (``ARROW_CAP``, from a jaw face
        holding the fruit, ``ARROW_CLEARANCE`` from it; a small fruit's)."""
        width = float(context.rest_width)
        centre = float(context.gripper_centre_x)
        plate = getattr(context, 'jaw_plate', None)
        # how far a jaw's face can stand behind the fruit's side: a Fin Ray's base
        # plate reaches from the face towards the fruit
        behind = (max(0.0, float(plate.centre[0]) + 0.5 * float(plate.size[0]))
                  if plate is not None else 0.0)
        arrow_end = centre - (0.5 * width + behind + ARROW_CAP + ARROW_CLEARANCE)
        legend = cls(bruise_pressure=float(context.bruise_pressure),
                     x=centre - 2.0 * width - LEGEND_LABEL_OFFSET, y=0.0,
                     z=float(context.table_height), height=width)
        overlap = legend.right_edge() - arrow_end
        if overlap > 0.0:
            legend = cls(bruise_pressure=legend.bruise_pressure, x=legend.x - overlap,
                         y=0.0, z=legend.z, height=width)
        return legend

    def right_edge(self) -> float:
        """m, the largest x of the bar and its labels (``legend_entity``)."""
        half_bar = 0.5 * LEGEND_BAR_WIDTH * self.height
        labels = max(text_extent(text, LEGEND_TEXT_SIZE)[0] for text, _ in _labels(self))
        title = text_extent(LEGEND_TITLE, LEGEND_TEXT_SIZE)[0]
        return max(self.x + half_bar + LEGEND_LABEL_GAP + labels,
                   self.x - half_bar + title)


def timestamp(stamp_ns: int) -> Timestamp:
    """A Foxglove ``Timestamp`` of integer nanoseconds."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return Timestamp(sec, nsec)


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _colour(colour: Any) -> Color:
    return Color(r=float(colour.r), g=float(colour.g), b=float(colour.b), a=float(colour.a))


def _point(point: Any) -> Point3:
    return Point3(x=float(point.x), y=float(point.y), z=float(point.z))


def _pose(pose: Any) -> Pose:
    p, q = pose.position, pose.orientation
    return Pose(position=Vector3(x=float(p.x), y=float(p.y), z=float(p.z)),
                orientation=Quaternion(x=float(q.x), y=float(q.y), z=float(q.z),
                                       w=float(q.w)))


def rotation_from_x(direction: tuple[float, float, float]) -> Quaternion:
    """The shortest rotation taking +x onto ``direction`` (need not be unit; nonzero).

    The half-way quaternion: w = 1 + d_x, (x, y, z) = x_hat cross d, normalised.
    """
    norm = math.sqrt(sum(c * c for c in direction))
    dx, dy, dz = (c / norm for c in direction)
    w, x, y, z = 1.0 + dx, 0.0, -dz, dy
    length = math.sqrt(w * w + x * x + y * y + z * z)
    if length < 1e-9:   # pointing along -x: half a turn about z
        return Quaternion(x=0.0, y=0.0, z=1.0, w=0.0)
    return Quaternion(x=x / length, y=y / length, z=z / length, w=w / length)


def _arrow(marker: Any) -> ArrowPrimitive | None:
    """An ARROW marker: from its two points (scale: shaft and head diameter, head length)
    or, without points, along the pose's x axis (scale: length, width, height). A jaw
    force arrow (ns ``JAW_FORCE_NS``, two points ``ARROW_SCALE`` m per N apart) is
    drawn ``jaw_arrow_length`` of its force long."""
    colour = _colour(marker.color)
    scale = marker.scale
    if len(marker.points) >= 2:
        start, end = marker.points[0], marker.points[1]
        direction = (end.x - start.x, end.y - start.y, end.z - start.z)
        length = math.sqrt(sum(c * c for c in direction))
        if length <= 0.0:
            return None
        if marker.ns == JAW_FORCE_NS:
            length = jaw_arrow_length(length / ARROW_SCALE)
        head = min(float(scale.z), length) if scale.z > 0 else 0.23 * length
        pose = Pose(position=Vector3(x=float(start.x), y=float(start.y), z=float(start.z)),
                    orientation=rotation_from_x(direction))
        return ArrowPrimitive(pose=pose, shaft_length=length - head,
                              shaft_diameter=float(scale.x), head_length=head,
                              head_diameter=float(scale.y), color=colour)
    length = float(scale.x)
    head = 0.23 * length
    return ArrowPrimitive(pose=_pose(marker.pose), shaft_length=length - head,
                          shaft_diameter=0.5 * float(scale.y), head_length=head,
                          head_diameter=float(scale.y), color=colour)


def _lines(marker: Any, line_type: Any) -> LinePrimitive:
    points = [_point(p) for p in marker.points]
    colours = [_colour(c) for c in marker.colors] if len(marker.colors) == len(points) else []
    return LinePrimitive(type=line_type, pose=_pose(marker.pose), thickness=float(marker.scale.x),
                         scale_invariant=False, points=points, color=_colour(marker.color),
                         colors=colours)


def _triangles(marker: Any) -> TriangleListPrimitive:
    points = [_point(p) for p in marker.points]
    colours = [_colour(c) for c in marker.colors] if len(marker.colors) == len(points) else []
    return TriangleListPrimitive(pose=_pose(marker.pose), points=points,
                                 color=_colour(marker.color), colors=colours)


def _size(marker: Any) -> Vector3:
    s = marker.scale
    return Vector3(x=float(s.x), y=float(s.y), z=float(s.z))


def marker_entity(marker: Any) -> SceneEntity | None:
    """The entity of one ADD marker, or None for a type the scene does not draw
    (CUBE_LIST, SPHERE_LIST, POINTS, MESH_RESOURCE: the node draws none of them)."""
    primitives: dict[str, list] = {}
    kind = int(marker.type)
    if kind == ARROW:
        arrow = _arrow(marker)
        if arrow is None:
            return None
        primitives['arrows'] = [arrow]
    elif kind == CUBE:
        primitives['cubes'] = [CubePrimitive(pose=_pose(marker.pose), size=_size(marker),
                                             color=_colour(marker.color))]
    elif kind == SPHERE:
        primitives['spheres'] = [SpherePrimitive(pose=_pose(marker.pose), size=_size(marker),
                                                 color=_colour(marker.color))]
    elif kind == CYLINDER:
        primitives['cylinders'] = [CylinderPrimitive(
            pose=_pose(marker.pose), size=_size(marker), bottom_scale=1.0, top_scale=1.0,
            color=_colour(marker.color))]
    elif kind == LINE_STRIP:
        primitives['lines'] = [_lines(marker, LinePrimitiveLineType.LineStrip)]
    elif kind == LINE_LIST:
        primitives['lines'] = [_lines(marker, LinePrimitiveLineType.LineList)]
    elif kind == TRIANGLE_LIST:
        primitives['triangles'] = [_triangles(marker)]
    elif kind == TEXT_VIEW_FACING:
        primitives['texts'] = [TextPrimitive(pose=_pose(marker.pose), billboard=True,
                                             font_size=float(marker.scale.z),
                                             scale_invariant=False,
                                             color=_colour(marker.color), text=marker.text)]
    else:
        return None
    return SceneEntity(timestamp=timestamp(_stamp_ns(marker.header)),
                       frame_id=marker.header.frame_id, id=f'{marker.ns}/{marker.id}',
                       frame_locked=bool(marker.frame_locked), **primitives)


def _text(text: str, x: float, y: float, z: float, size: float) -> TextPrimitive:
    return TextPrimitive(pose=Pose(position=Vector3(x=x, y=y, z=z),
                                   orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                         billboard=True, font_size=size, scale_invariant=False,
                         color=Color(r=0.1, g=0.1, b=0.1, a=1.0), text=text)


def _left_text(text: str, left: float, y: float, z: float, size: float) -> TextPrimitive:
    """``text`` starting at x = ``left`` (m): Foxglove centres a text on its pose."""
    return _text(text, left + 0.5 * text_extent(text, size)[0], y, z, size)


def _labels(legend: PressureLegend) -> list[tuple[str, float]]:
    """(text, z) of the colour bar's value labels."""
    kpa = legend.bruise_pressure / 1e3
    return [('0 kPa', legend.z), (f'{0.5 * kpa:.0f} kPa', legend.z + 0.5 * legend.height),
            (f'>= {kpa:.0f} kPa (bruise)', legend.z + legend.height)]


def legend_entity(legend: PressureLegend, stamp_ns: int) -> SceneEntity:
    """The colour bar of the fruit's contact pressure with its labels (``legend/pressure``).

    Cube k of ``LEGEND_STEPS`` shows the colour of pressure (k + 1/2) / steps times the
    bruise pressure (``pressure_colour``): green at 0, yellow at half, red at the bruise
    pressure and above.
    """
    step = legend.height / LEGEND_STEPS
    width = LEGEND_BAR_WIDTH * legend.height
    cubes = []
    for k in range(LEGEND_STEPS):
        colour = pressure_colour((k + 0.5) / LEGEND_STEPS * legend.bruise_pressure,
                                 legend.bruise_pressure)
        centre = Vector3(x=legend.x, y=legend.y, z=legend.z + (k + 0.5) * step)
        cubes.append(CubePrimitive(
            pose=Pose(position=centre, orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            size=Vector3(x=width, y=width, z=step), color=_colour(colour)))
    label_left = legend.x + 0.5 * width + LEGEND_LABEL_GAP
    texts = [_left_text(text, label_left, legend.y, z, LEGEND_TEXT_SIZE)
             for text, z in _labels(legend)]
    texts.append(_left_text(LEGEND_TITLE, legend.x - 0.5 * width, legend.y,
                            legend.z + legend.height + 2.5 * LEGEND_TEXT_SIZE,
                            LEGEND_TEXT_SIZE))
    return SceneEntity(timestamp=timestamp(stamp_ns), frame_id=legend.frame_id,
                       id='legend/pressure', cubes=cubes, texts=texts)


def state_text(state: Any) -> str:
    """A ``FruitState`` in short lines: grip force, compression, slip, peak pressure (and
    SLIPPING while it slips). In one line it was about four fruit widths long and ran
    out of the layout's view."""
    lines = [f'grip {state.grip_force:.2f} N',
             f'compression {1e3 * state.compression:.2f} mm',
             f'slip {1e3 * state.slip_distance:.2f} mm',
             f'peak pressure {state.damage_pressure / 1e3:.0f} kPa']
    return '\n'.join(lines + (['SLIPPING'] if state.slipping else []))


def state_entity(state: Any, legend: PressureLegend) -> SceneEntity:
    """``legend/state``: ``state_text`` above the fruit's centroid, a fruit width up
    and at least so far that its lowest line clears a jaw force arrow at the centroid's
    height pointing up (``ARROW_CAP`` and ``ARROW_CLEARANCE``: a small fruit's)."""
    centroid = state.centroid
    text = state_text(state)
    half_height = 0.5 * text_extent(text, STATE_TEXT_SIZE)[1]
    above = max(legend.height, ARROW_CAP + ARROW_CLEARANCE + half_height)
    return SceneEntity(
        timestamp=timestamp(_stamp_ns(state.header)), frame_id=legend.frame_id,
        id='legend/state',
        texts=[_text(text, float(centroid.x), float(centroid.y),
                     float(centroid.z) + above, STATE_TEXT_SIZE)])


def scene_update(markers: Iterable[Any], *, legend: PressureLegend | None = None,
                 fruit_state: Any = None, stamp_ns: int = 0) -> SceneUpdate:
    """The ``SceneUpdate`` of the node's markers (a ``MarkerArray``'s ``markers``).

    Args:
        markers: ``visualization_msgs/Marker`` objects (or any with their fields).
        legend: add the pressure colour bar (``legend_entity``); None = not.
        fruit_state: a ``FruitState`` to write above the fruit (``state_entity``;
            needs ``legend`` for the frame and height); None = not.
        stamp_ns: ns, timestamp of the legend and of the deletions of DELETEALL.

    A DELETE marker deletes entity ``<ns>/<id>``; DELETEALL deletes every entity.
    """
    entities: list[SceneEntity] = []
    deletions: list[SceneEntityDeletion] = []
    for marker in markers:
        action = int(marker.action)
        if action == DELETE:
            deletions.append(SceneEntityDeletion(
                timestamp=timestamp(_stamp_ns(marker.header)),
                type=SceneEntityDeletionType.MatchingId, id=f'{marker.ns}/{marker.id}'))
        elif action == DELETEALL:
            deletions.append(SceneEntityDeletion(timestamp=timestamp(stamp_ns),
                                                 type=SceneEntityDeletionType.All, id=''))
        else:
            entity = marker_entity(marker)
            if entity is not None:
                entities.append(entity)
    if legend is not None:
        entities.append(legend_entity(legend, stamp_ns))
        if fruit_state is not None:
            entities.append(state_entity(fruit_state, legend))
    return SceneUpdate(deletions=deletions, entities=entities)


def scene_of_batch(batch: Mapping[str, Any], legend: PressureLegend | None,
                   stamp_ns: int) -> SceneUpdate | None:
    """The scene of a batch ``{topic suffix: message}`` (``messages.build_messages``):
    from its ``markers`` and ``fruit/state``; None without markers."""
    array = batch.get('markers')
    if array is None:
        return None
    return scene_update(array.markers, legend=legend, fruit_state=batch.get('fruit/state'),
                        stamp_ns=stamp_ns)
