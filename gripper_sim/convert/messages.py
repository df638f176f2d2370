"""Pure conversion of a ``StepResult`` to the ROS messages the node publishes.

No node, no publishing: the ``gripper_sim`` node and the offline MCAP writer both call
``build_messages`` so that a live run and an offline recording carry the same topics
with the same contents.

Conventions (REP 103): SI units; the planar model (``dimension`` 2) lives in the x-z
plane of the world frame and is published as 3D data with y = 0; the 3D model
(``StepResult3D``: (n, 3) positions) is published as it is. Frames
(``convert.frames``, after the context's ``frame_prefix``): ``<p>world`` (``world``
without a prefix) for the fruit, the markers and the table; ``<p>left_jaw`` /
``<p>right_jaw`` for the jaw wrenches (parallel to ``world``, origin at the centre of
the jaw face). ``/tf`` carries the moving edges of that tree with every batch.

The fruit marker: a 2D result draws the outline (ns ``fruit_outline``, LINE_STRIP), a
3D result the skin (ns ``fruit_mesh``, TRIANGLE_LIST, three points per skin triangle),
both coloured per point by the contact pressure there (``node_pressure``: the damage
estimate's; ``pressure_colour``: red at and above the bruise pressure). Shaped fingers
and pads: ``finger_markers``. ``FruitState`` damage fields come from the step's damage
estimate (``StepResult.damage``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, TransformStamped, WrenchStamped
from gripper_sim_interfaces.msg import FruitState
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import Marker, MarkerArray

from gripper_sim.convert import frames as frame_tree
from gripper_sim.convert.finger_markers import (FingerGeometry, JawPlate, base_marker,
                                            fin_ray_jaw_plate, finger_geometry,
                                            finger_markers, rigid_jaw_plate)
from gripper_sim.convert.frames import FrameTransform, GripperFrames
from gripper_sim.core.gripper import lift_range, transport_range
from gripper_sim.core.results import StepResult

JOINT_NAMES = frame_tree.JOINT_NAMES
DEFAULT_NODE_NAME = 'gripper_sim'

# suffix -> (name as the node creates it, ROS type). Names starting with '~/' are
# private to the node, 'joint_states' is relative to its namespace, '/clock' absolute.
TOPICS: dict[str, tuple[str, str]] = {
    'fruit/nodes': ('~/fruit/nodes', 'sensor_msgs/msg/PointCloud2'),
    'fruit/state': ('~/fruit/state', 'gripper_sim_interfaces/msg/FruitState'),
    'left_jaw/wrench': ('~/left_jaw/wrench', 'geometry_msgs/msg/WrenchStamped'),
    'right_jaw/wrench': ('~/right_jaw/wrench', 'geometry_msgs/msg/WrenchStamped'),
    'joint_states': ('joint_states', 'sensor_msgs/msg/JointState'),
    'markers': ('~/markers', 'visualization_msgs/msg/MarkerArray'),
    'clock': ('/clock', 'rosgraph_msgs/msg/Clock'),
    'tf': ('/tf', 'tf2_msgs/msg/TFMessage'),
}

MESSAGE_CLASSES = {
    'fruit/nodes': PointCloud2,
    'fruit/state': FruitState,
    'left_jaw/wrench': WrenchStamped,
    'right_jaw/wrench': WrenchStamped,
    'joint_states': JointState,
    'markers': MarkerArray,
    'clock': Clock,
    'tf': TFMessage,
}

# Point cloud layout: six float32 fields, 24 bytes a point.
POINT_FIELDS = ('x', 'y', 'z', 'fx', 'fy', 'fz')
POINT_STEP = 4 * len(POINT_FIELDS)

ARROW_SCALE = 0.005          # m of arrow per N of jaw force
CONTACT_LINE_SCALE = 0.01    # m of line per N of node contact force
OUTLINE_WIDTH = 0.001        # m


def resolved_topic(suffix: str, node_name: str = DEFAULT_NODE_NAME,
                   namespace: str = '/') -> str:
    """Fully qualified name of topic ``suffix`` for a node ``node_name`` in ``namespace``.

    >>> resolved_topic('fruit/state')
    '/gripper_sim/fruit/state'
    >>> resolved_topic('joint_states', namespace='/robot')
    '/robot/joint_states'
    """
    name = TOPICS[suffix][0]
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    if name.startswith('/'):
        return name
    if name.startswith('~/'):
        return f'{ns}/{node_name}/{name[2:]}'
    return f'{ns}/{name}'


def time_msg(stamp: Any) -> Time:
    """A ``builtin_interfaces/Time`` from a Time message, integer ns or float seconds."""
    if isinstance(stamp, Time):
        return stamp
    if isinstance(stamp, (int, np.integer)):
        ns = int(stamp)
    else:
        ns = int(round(float(stamp) * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def result_is_finite(result: StepResult) -> bool:
    """Whether every published quantity of ``result`` is finite (never publish NaN).

    Called on every physics step by the node: one vectorised check of the arrays.
    """
    deformation, energies = result.deformation, result.energies
    scalars = (result.time, result.left_jaw_x, result.right_jaw_x, result.jaw_velocity,
               result.lift, result.lift_velocity, result.gap, result.grip_force,
               result.slip_distance, energies.kinetic, energies.elastic,
               energies.gravitational, deformation.compression,
               deformation.compression_ratio, deformation.max_skin_strain,
               deformation.contact_length, deformation.peak_contact_pressure)
    if result.damage is not None:
        damage = result.damage
        scalars += (damage.pressure, damage.peak_pressure, damage.peak_flesh_stress,
                    damage.bruised_fraction)
    if not all(map(math.isfinite, scalars)):
        return False
    arrays = (result.positions, result.velocities, result.contact_forces, result.centroid,
              result.left_wrench.force, result.left_wrench.torque,
              result.right_wrench.force, result.right_wrench.torque,
              deformation.node_pressure)
    return bool(np.isfinite(np.concatenate([np.ravel(a) for a in arrays])).all())


@dataclass
class MessageContext:
    """What the messages need beyond one step result: geometry, thresholds, history.

    Build it once per run with ``from_config`` and call ``observe`` after every step
    (``build_messages`` also calls it). For a result without a damage estimate
    (``result.damage`` None, e.g. a hand-made one) it latches its own from the model's
    contact pressure: ``bruised``, ``crushed``, ``peak_pressure`` and
    ``bruised_fraction`` over the run, cleared by ``reset``. Results of the core carry
    ``damage`` and ``FruitState`` reports that instead.

    Attributes:
        dimension: model dimension (2 = planar x-z).
        rest_width: m, fruit rest diameter.
        depth: m, out-of-plane depth of the planar model (turns length into area).
        bruise_pressure: Pa, contact pressure above which the fruit bruises.
        failure_stress: Pa, flesh failure stress (compared with peak contact pressure).
        jaw_height, jaw_thickness: m, jaw face length along z and thickness along x.
        jaw_width: m, 3D jaw face width along y (the 2D jaws are drawn ``depth`` wide).
        table: whether there is a table, at ``table_height`` (m).
        gripper_centre_x: m, x of the gripper centre the jaw joints are measured from.
        finger: the shaped finger / pad to draw (``finger_markers.finger_geometry``);
            None for flat jaws without pads and for deformable fingers.
        plate: the jaw plate (``finger_markers.JawPlate``) where it is not the rigid
            finger's: a Fin Ray's, on its base (``finger_markers.fin_ray_jaw_plate``);
            None: the rigid finger's (``finger_markers.rigid_jaw_plate``; ``jaw_plate``
            gives the one drawn).
        frames: the TF frame names (``frame_prefix``) and the jaw joints' directions.
    """

    dimension: int = 2
    rest_width: float = 0.0635
    depth: float = 0.0635 * 2.0 / 3.0
    bruise_pressure: float = 0.26e6
    failure_stress: float = 0.29e6
    jaw_height: float = 0.04
    jaw_thickness: float = 0.01
    jaw_width: float = 0.04
    table: bool = True
    table_height: float = 0.0
    gripper_centre_x: float = 0.0
    finger: FingerGeometry | None = None
    plate: JawPlate | None = None
    frames: GripperFrames = field(default_factory=GripperFrames)
    bruised: bool = field(default=False, init=False)
    crushed: bool = field(default=False, init=False)
    peak_pressure: float = field(default=0.0, init=False)
    _node_bruised: np.ndarray | None = field(default=None, init=False, repr=False)

    @classmethod
    def from_config(cls, config: Mapping[str, Any], initial: StepResult | None = None,
                    frame_prefix: str = '') -> 'MessageContext':
        """Context of a run of configuration ``config`` (flat, from ``load_config``).

        Args:
            config: the flat configuration of the simulation.
            initial: the result of the initial state (``Simulation.last`` before any
                step); the gripper centre is the midpoint of its jaw faces.
            frame_prefix: prepended to every frame id (``convert.frames.check_prefix``).

        Raises:
            FrameError: ``frame_prefix`` is not valid.
        """
        diameter = float(config.get('fruit.shape.diameter', cls.rest_width))
        depth = config.get('fruit.depth')
        centre = 0.0
        left_outward = -1.0
        if initial is not None:
            centre = 0.5 * (float(initial.left_jaw_x) + float(initial.right_jaw_x))
            left_outward = -1.0 if _left_is_negative(initial) else 1.0
        table = bool(config.get('world.table', True))
        jaw_thickness = float(config.get('gripper.jaw_thickness', cls.jaw_thickness))
        jaw_height = float(config.get('gripper.jaw_height', cls.jaw_height))
        table_height = float(config.get('world.table_height', 0.0))
        finger = finger_geometry(config)
        plate = (fin_ray_jaw_plate(config, jaw_thickness)
                 if config.get('gripper.finger.type') == 'fin_ray' else None)
        jaw_plate = plate or rigid_jaw_plate(finger, jaw_thickness, jaw_height)
        frames = GripperFrames(
            prefix=frame_prefix, left_outward=left_outward,
            jaw_height=jaw_height,
            jaw_width=float(config.get('gripper.jaw_width', cls.jaw_width)),
            jaw_thickness=jaw_thickness,
            max_gap=float(config.get('gripper.max_gap', GripperFrames.max_gap)),
            table_height=table_height if table else None,
            plate=(jaw_plate.centre, jaw_plate.size), **_travel_ranges(config))
        return cls(
            dimension=int(config.get('dimension', 2)),
            rest_width=diameter,
            depth=float(depth) if depth is not None else diameter * 2.0 / 3.0,
            bruise_pressure=float(config.get('fruit.bruise_pressure', cls.bruise_pressure)),
            failure_stress=float(config.get('fruit.failure_stress', cls.failure_stress)),
            jaw_height=jaw_height,
            jaw_thickness=jaw_thickness,
            jaw_width=float(config.get('gripper.jaw_width', cls.jaw_width)),
            table=table,
            table_height=table_height,
            gripper_centre_x=centre,
            finger=finger,
            plate=plate,
            frames=frames,
        )

    @property
    def jaw_plate(self) -> JawPlate:
        """The left jaw's plate in its jaw frame (``plate``, else the rigid finger's)."""
        if self.plate is not None:
            return self.plate
        return rigid_jaw_plate(self.finger, self.jaw_thickness, self.jaw_height)

    def reset(self) -> None:
        """Forget the run history (after a simulation reset)."""
        self.bruised = False
        self.crushed = False
        self.peak_pressure = 0.0
        self._node_bruised = None

    def snapshot(self) -> 'MessageContext':
        """A copy of the run history as it is now, for building messages later.

        The node builds a step's messages outside its simulation lock while the
        physics goes on (or a reset clears the history): they read this copy.
        """
        copy = dataclasses.replace(self)
        copy.bruised, copy.crushed = self.bruised, self.crushed
        copy.peak_pressure = self.peak_pressure
        if self._node_bruised is not None:
            copy._node_bruised = self._node_bruised.copy()
        return copy

    def observe(self, result: StepResult) -> None:
        """Latch bruising and crushing from ``result`` into the run history."""
        deformation = result.deformation
        self.peak_pressure = max(self.peak_pressure, float(deformation.peak_contact_pressure))
        if deformation.peak_contact_pressure > self.bruise_pressure:
            self.bruised = True
        if deformation.peak_contact_pressure > self.failure_stress:
            self.crushed = True
        over = np.asarray(deformation.node_pressure) > self.bruise_pressure
        if self._node_bruised is None or self._node_bruised.shape != over.shape:
            self._node_bruised = over.copy()
        else:
            self._node_bruised |= over

    @property
    def bruised_fraction(self) -> float:
        """Fraction of the surface nodes that have been above the bruise pressure."""
        if self._node_bruised is None or self._node_bruised.size == 0:
            return 0.0
        return float(np.count_nonzero(self._node_bruised)) / self._node_bruised.size


def is_3d(result: StepResult) -> bool:
    """Whether ``result`` comes from the 3D model ((n, 3) positions)."""
    return np.ndim(result.positions) == 2 and np.shape(result.positions)[1] == 3


def world_xyz(vectors: np.ndarray) -> np.ndarray:
    """(n, 3) float world vectors of (n, 2) planar (x, z) ones (y = 0) or (n, 3) ones."""
    vectors = np.asarray(vectors, dtype=float)
    if vectors.ndim == 2 and vectors.shape[1] == 3:
        return vectors
    out = np.zeros((vectors.shape[0], 3))
    out[:, 0], out[:, 2] = vectors[:, 0], vectors[:, 1]
    return out


def node_pressure(result: StepResult) -> np.ndarray:
    """(n_nodes,) Pa, contact pressure at every fruit node (0 off the surface).

    The damage estimate's pressure (``result.damage.node_pressure``: the Hertz/ASAE
    estimate in 2D, the resolved normal force over vertex area in 3D) when the step
    has one, else the model's own ``deformation.node_pressure``.
    """
    source = result.damage if result.damage is not None else result.deformation
    surface_pressure = np.asarray(source.node_pressure, dtype=float)
    full = np.zeros(np.shape(result.positions)[0])
    surface = np.asarray(result.surface, dtype=int)
    if surface_pressure.shape == surface.shape:
        full[surface] = surface_pressure
    return full


#: the configuration keys the lift and transport ranges are made of
_TRAVEL_KEYS = ('world.table', 'world.table_height', 'gripper.jaw_height', 'world.walls',
                'world.wall_half_width')


def _travel_ranges(config: Mapping[str, Any]) -> dict:
    """``GripperFrames``' ``lift_range`` and ``transport_range`` (m) of ``config``: what
    the simulation accepts (``core.gripper``); its defaults where ``config`` lacks a key
    they are made of (a partial mapping)."""
    if not all(key in config for key in _TRAVEL_KEYS):
        return {}
    return dict(lift_range=lift_range(config), transport_range=transport_range(config))


def _left_is_negative(result: StepResult) -> bool:
    return result.left_jaw_x <= result.right_jaw_x


def jaw_normal_forces(result: StepResult) -> tuple[float, float]:
    """Contact normal force (N) the fruit pushes each jaw outwards with (left, right)."""
    outward_left = -1.0 if _left_is_negative(result) else 1.0
    left = float(result.left_wrench.force[0]) * outward_left
    right = float(result.right_wrench.force[0]) * -outward_left
    return left + 0.0, right + 0.0   # + 0.0: no negative zero


def point_cloud(result: StepResult, header: Header) -> PointCloud2:
    """One point per fruit node: fields x y z fx fy fz (float32; m and N; y = 0 in 2D)."""
    n = result.positions.shape[0]
    data = np.zeros((n, len(POINT_FIELDS)), dtype=np.float32)
    data[:, 0:3] = world_xyz(result.positions)
    data[:, 3:6] = world_xyz(result.contact_forces)
    msg = PointCloud2()
    msg.header = header
    msg.height = 1
    msg.width = n
    msg.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, name in enumerate(POINT_FIELDS)]
    msg.is_bigendian = False
    msg.point_step = POINT_STEP
    msg.row_step = POINT_STEP * n
    msg.data = data.tobytes()
    msg.is_dense = True
    return msg


def read_point_cloud(msg: PointCloud2) -> np.ndarray:
    """The (n, 6) float32 array x y z fx fy fz of a cloud made by ``point_cloud``."""
    names = [f.name for f in msg.fields]
    if names != list(POINT_FIELDS) or msg.point_step != POINT_STEP:
        raise ValueError(f'not a gripper_sim node cloud: fields {names}')
    return np.frombuffer(bytes(msg.data), dtype='<f4').reshape(-1, len(POINT_FIELDS))


def fruit_state(result: StepResult, context: MessageContext, header: Header) -> FruitState:
    """The ``FruitState`` of ``result`` (see the .msg for the fields and units)."""
    deformation = result.deformation
    msg = FruitState()
    msg.header = header
    msg.dimension = 3 if is_3d(result) else 2
    msg.node_count = int(result.positions.shape[0])
    msg.compression = float(deformation.compression)
    msg.compression_ratio = float(deformation.compression_ratio)
    msg.max_skin_strain = float(deformation.max_skin_strain)
    msg.contact_length = float(deformation.contact_length)
    if hasattr(deformation, 'contact_area'):
        msg.contact_area = float(deformation.contact_area)
    else:
        # The planar model is a slab of depth b: its contact area is length x depth.
        msg.contact_area = float(deformation.contact_length) * context.depth
    msg.peak_contact_pressure = float(deformation.peak_contact_pressure)
    msg.elastic_energy = float(result.energies.elastic)
    msg.kinetic_energy = float(result.energies.kinetic)
    msg.gravitational_energy = float(result.energies.gravitational)
    x, y, z = world_xyz(np.reshape(result.centroid, (1, -1)))[0].tolist()
    msg.centroid = Point(x=x, y=y, z=z)
    msg.grip_force = float(result.grip_force)
    msg.gap = float(result.gap)
    msg.slip_distance = float(result.slip_distance)
    msg.left_jaw_contact = result.in_contact_with('left_jaw')
    msg.right_jaw_contact = result.in_contact_with('right_jaw')
    msg.slipping = bool(result.slipping)
    damage = result.damage
    if damage is not None:   # the core's damage estimate, cumulative since the reset
        msg.damage_pressure = float(damage.pressure)
        msg.peak_damage_pressure = float(damage.peak_pressure)
        msg.peak_flesh_stress = float(damage.peak_flesh_stress)
        msg.bruised = bool(damage.bruised)
        msg.bruised_fraction = float(damage.bruised_fraction)
        msg.crushed = bool(damage.crushed)
    else:                    # a producer without one: the model's own contact pressure
        msg.damage_pressure = float(deformation.peak_contact_pressure)
        msg.peak_damage_pressure = context.peak_pressure
        msg.bruised = context.bruised
        msg.bruised_fraction = context.bruised_fraction
        msg.crushed = context.crushed
    return msg


def jaw_wrench(result: StepResult, side: str, stamp: Time,
               frames: GripperFrames = GripperFrames()) -> WrenchStamped:
    """Net wrench the fruit exerts on jaw ``side`` ('left' or 'right'), in its frame."""
    wrench = result.left_wrench if side == 'left' else result.right_wrench
    msg = WrenchStamped()
    msg.header = Header(stamp=stamp, frame_id=frames.left_jaw if side == 'left'
                        else frames.right_jaw)
    force, torque = wrench.force, wrench.torque
    msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = (float(v) for v in force)
    msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z = (float(v) for v in torque)
    return msg


def joint_state(result: StepResult, context: MessageContext, stamp: Time) -> JointState:
    """The joints of ``convert.frames`` (and of the URDF): jaws, m from the gripper
    centre (positive = open); lift: height (m); transport: the gripper centre's x (m).

    Effort: the contact normal force on each jaw (N, positive when the fruit pushes
    the jaw open); for ``lift_joint`` the vertical load the fruit puts on the jaws
    (N, positive when the gripper carries the fruit's weight); for
    ``transport_joint`` the force along x that holds the fruit's sideways push on the
    jaws (N, positive along +x).
    """
    positions = frame_tree.joint_positions(result, context.frames)
    left_force, right_force = jaw_normal_forces(result)
    load = -float(result.left_wrench.force[2] + result.right_wrench.force[2]) + 0.0
    sideways = -float(result.left_wrench.force[0] + result.right_wrench.force[0]) + 0.0
    msg = JointState()
    msg.header = Header(stamp=stamp, frame_id='')
    msg.name = list(JOINT_NAMES)
    msg.position = [positions[name] for name in JOINT_NAMES]
    opening = -float(result.jaw_velocity)
    msg.velocity = [opening, opening, float(result.lift_velocity),
                    float(result.gripper_x_velocity)]
    msg.effort = [left_force, right_force, load, sideways]
    return msg


def transform_message(transforms: Iterable[FrameTransform], stamp: Time) -> TFMessage:
    """A ``tf2_msgs/TFMessage`` of ``transforms`` (``convert.frames``), all at ``stamp``."""
    msg = TFMessage()
    for edge in transforms:
        stamped = TransformStamped()
        stamped.header = Header(stamp=stamp, frame_id=edge.parent)
        stamped.child_frame_id = edge.child
        t, q = stamped.transform.translation, stamped.transform.rotation
        t.x, t.y, t.z = (float(v) for v in edge.translation)
        q.x, q.y, q.z, q.w = (float(v) for v in edge.rotation)
        msg.transforms.append(stamped)
    return msg


def pressure_colour(pressure: float, bruise_pressure: float) -> ColorRGBA:
    """Green at zero pressure, yellow at half the bruise pressure, red at and above it."""
    scale = bruise_pressure if bruise_pressure > 0 else 1.0
    s = min(max(pressure / scale, 0.0), 1.0)
    if s < 0.5:
        return ColorRGBA(r=float(0.2 + 1.6 * s), g=0.8, b=0.2, a=1.0)
    return ColorRGBA(r=1.0, g=float(0.8 * (2.0 - 2.0 * s)), b=0.2, a=1.0)


def _pressure_colours(pressure: np.ndarray, bruise_pressure: float) -> list[ColorRGBA]:
    """``pressure_colour`` of every value, vectorised; nodes of one colour share it."""
    scale = bruise_pressure if bruise_pressure > 0 else 1.0
    s = np.clip(np.asarray(pressure, dtype=float) / scale, 0.0, 1.0)
    low = s < 0.5
    red = np.where(low, 0.2 + 1.6 * s, 1.0)
    green = np.where(low, 0.8, 0.8 * (2.0 - 2.0 * s))
    made: dict[tuple[float, float], ColorRGBA] = {}
    colours = []
    for key in zip(red.tolist(), green.tolist()):
        colour = made.get(key)
        if colour is None:
            colour = made[key] = ColorRGBA(r=key[0], g=key[1], b=0.2, a=1.0)
        colours.append(colour)
    return colours


def _deleted(header: Header, ns: str, marker_id: int) -> Marker:
    marker = base_marker(header, ns, marker_id, Marker.ARROW)
    marker.action = Marker.DELETE
    return marker


def _points(xyz: np.ndarray) -> list[Point]:
    """``Point``s of an (n, 3) array."""
    return [Point(x=x, y=y, z=z) for x, y, z in np.asarray(xyz, dtype=float).tolist()]


def fruit_marker(result: StepResult, context: MessageContext, header: Header) -> Marker:
    """The fruit coloured by contact pressure: 2D outline or 3D skin (module docstring).

    3D: ns ``fruit_mesh``, id 0, TRIANGLE_LIST whose points are the corners of
    ``result.triangles`` in order (3 per triangle) and colours the pressure colour of
    each corner's node. 2D: ns ``fruit_outline``, id 0, a closed LINE_STRIP.
    """
    pressure = node_pressure(result)
    positions = world_xyz(result.positions)
    if is_3d(result):
        corners = np.asarray(result.triangles, dtype=int).ravel()
        marker = base_marker(header, 'fruit_mesh', 0, Marker.TRIANGLE_LIST)
        marker.scale.x = marker.scale.y = marker.scale.z = 1.0
    else:
        surface = np.asarray(result.surface, dtype=int)
        corners = np.concatenate([surface, surface[:1]])
        marker = base_marker(header, 'fruit_outline', 0, Marker.LINE_STRIP)
        marker.scale.x = OUTLINE_WIDTH
    marker.points = _points(positions[corners])
    marker.colors = _pressure_colours(pressure[corners], context.bruise_pressure)
    marker.color = ColorRGBA(r=0.2, g=0.8, b=0.2, a=1.0)
    return marker


def soft_finger_marker(result: StepResult, header: Header) -> Marker:
    """ns ``soft_fingers`` id 0, LINE_LIST: the deformable fingers whole
    (``StepResult.fingers``: ``drawn_edges``, a Fin Ray's beams and ribs, a solid pad's
    outline), as they deform, in the plane y = 0 (3D: the edges of their surface
    triangles)."""
    fingers = result.fingers
    edges = fingers.surface_edges if fingers.drawn_edges is None else fingers.drawn_edges
    lines = base_marker(header, 'soft_fingers', 0, Marker.LINE_LIST)
    lines.scale.x = OUTLINE_WIDTH
    lines.color = ColorRGBA(r=0.15, g=0.35, b=0.75, a=1.0)
    lines.points = _points(world_xyz(fingers.positions)[edges.ravel()])
    return lines


def markers(result: StepResult, context: MessageContext, header: Header) -> MarkerArray:
    """Fruit coloured by contact pressure, jaws, shaped fingers and pads
    (``finger_markers``), deformable fingers (``soft_finger_marker``), table, force arrows
    (frame ``world``)."""
    array = MarkerArray()
    array.markers.append(fruit_marker(result, context, header))

    outward_left = -1.0 if _left_is_negative(result) else 1.0
    depth = max(context.depth, 1e-3)
    width = context.jaw_width if is_3d(result) else depth
    jaws = (('left', result.left_jaw_x, outward_left, result.left_wrench),
            ('right', result.right_jaw_x, -outward_left, result.right_wrench))
    # behind a recessed face and a pad, on a Fin Ray's base (``JawPlate``)
    plate = context.jaw_plate
    for marker_id, (_, face_x, outward, wrench) in enumerate(jaws):
        jaw = base_marker(header, 'jaws', marker_id, Marker.CUBE)
        jaw.pose.position.x = float(face_x - outward * plate.centre[0])
        jaw.pose.position.z = float(result.lift + plate.centre[1])
        jaw.scale.x = plate.size[0]
        jaw.scale.y = width
        jaw.scale.z = plate.size[1]
        jaw.color = ColorRGBA(r=0.45, g=0.45, b=0.5, a=0.8)
        array.markers.append(jaw)

        force = np.asarray(wrench.force, dtype=float)
        if float(np.linalg.norm(force)) < 1e-9:
            array.markers.append(_deleted(header, 'jaw_forces', marker_id))
            continue
        arrow = base_marker(header, 'jaw_forces', marker_id, Marker.ARROW)
        start = Point(x=float(face_x), y=0.0, z=float(result.lift))
        arrow.points = [start, Point(x=start.x + ARROW_SCALE * force[0],
                                     y=ARROW_SCALE * force[1],
                                     z=start.z + ARROW_SCALE * force[2])]
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.002, 0.004, 0.004
        arrow.color = ColorRGBA(r=0.9, g=0.3, b=0.1, a=1.0)
        array.markers.append(arrow)

    array.markers.extend(finger_markers(
        context.finger, header, [(float(face_x), -outward) for _, face_x, outward, _ in jaws],
        float(result.lift), width))
    if result.fingers is not None:
        array.markers.append(soft_finger_marker(result, header))

    if context.table:
        table = base_marker(header, 'table', 0, Marker.CUBE)
        span = max(0.3, 4.0 * context.rest_width)
        table.pose.position.z = context.table_height - 0.005
        table.scale.x, table.scale.y, table.scale.z = span, max(2.0 * width, span / 2), 0.01
        table.color = ColorRGBA(r=0.55, g=0.4, b=0.25, a=1.0)
        array.markers.append(table)

    touching = np.flatnonzero(np.asarray(result.contact_obstacle) >= 0)
    if touching.size:
        lines = base_marker(header, 'contact_forces', 0, Marker.LINE_LIST)
        lines.scale.x = 0.0005
        lines.color = ColorRGBA(r=0.1, g=0.3, b=0.9, a=1.0)
        start = world_xyz(result.positions)[touching]
        end = start + CONTACT_LINE_SCALE * world_xyz(result.contact_forces)[touching]
        lines.points = _points(np.stack([start, end], axis=1).reshape(-1, 3))
        array.markers.append(lines)
    else:
        array.markers.append(_deleted(header, 'contact_forces', 0))
    return array


def build_messages(result: StepResult, context: MessageContext | Mapping[str, Any],
                   stamp: Any = None, topics: Iterable[str] | None = None) -> dict[str, Any]:
    """Every message the node publishes for ``result``, keyed by topic suffix.

    Args:
        result: the step to convert.
        context: a ``MessageContext`` (keeps the run history: use one per run), or a
            flat configuration mapping (a fresh context, no history beyond ``result``).
        stamp: header stamp in sim time: a ``builtin_interfaces/Time``, integer ns
            or float s; None = ``result.time``.
        topics: suffixes to build (keys of ``TOPICS``); None = all.

    Returns:
        ``{suffix: message}`` with suffixes from ``TOPICS`` ('fruit/nodes',
        'fruit/state', 'left_jaw/wrench', 'right_jaw/wrench', 'joint_states',
        'markers', 'clock', 'tf'); ``resolved_topic(suffix)`` gives the topic name.
    """
    if not isinstance(context, MessageContext):
        context = MessageContext.from_config(context)
    context.observe(result)
    wanted = set(TOPICS) if topics is None else set(topics)
    unknown = wanted - set(TOPICS)
    if unknown:
        raise ValueError(f"unknown topic suffix(es): {', '.join(sorted(unknown))}")
    time = time_msg(result.time if stamp is None else stamp)
    frames = context.frames
    world = Header(stamp=time, frame_id=frames.scene)
    out: dict[str, Any] = {}
    if 'fruit/nodes' in wanted:
        out['fruit/nodes'] = point_cloud(result, world)
    if 'fruit/state' in wanted:
        out['fruit/state'] = fruit_state(result, context, world)
    if 'left_jaw/wrench' in wanted:
        out['left_jaw/wrench'] = jaw_wrench(result, 'left', time, frames)
    if 'right_jaw/wrench' in wanted:
        out['right_jaw/wrench'] = jaw_wrench(result, 'right', time, frames)
    if 'joint_states' in wanted:
        out['joint_states'] = joint_state(result, context, time)
    if 'markers' in wanted:
        out['markers'] = markers(result, context, world)
    if 'clock' in wanted:
        out['clock'] = Clock(clock=time)
    if 'tf' in wanted:
        out['tf'] = transform_message(frame_tree.dynamic_transforms(result, frames), time)
    return out
