"""The gripper's TF tree and joint positions from a ``StepResult`` (no rclpy).

Tree (REP 103 axes, every frame parallel to ``world``, so every rotation is the
identity; names after the ``frame_prefix``)::

    world
    ├─ <p>world            fixed, identical to world (only with a prefix): the fruit's,
    │                      the markers' and the table's frame
    ├─ <p>table            fixed, the table surface (when there is a table)
    └─ <p>carriage         transport_joint: prismatic along x, the gripper centre's x
       └─ <p>gripper_base  lift_joint: prismatic along z, the jaw centre's height
          ├─ <p>left_jaw   left_jaw_joint: prismatic, outwards, m from the centre (open > 0)
          └─ <p>right_jaw  right_jaw_joint: likewise on the other side

A jaw frame's origin is the centre of its jaw face, the frame the node's jaw wrenches
are expressed in. ``world`` is shared by every gripper (no prefix): two grippers with
prefixes ``g1/`` and ``g2/`` hang their own subtrees from it. The planar model lives in
the x-z plane (y = 0). The joint names and positions are those of ``/joint_states``
(``left_jaw_joint``, ``right_jaw_joint``, ``lift_joint``) plus ``transport_joint``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from gripper_sim.core.gripper import FREE_TRAVEL, lift_range, transport_range
from gripper_sim.errors import GripperSimError

WORLD_FRAME = 'world'
IDENTITY = (0.0, 0.0, 0.0, 1.0)   # quaternion x, y, z, w
JOINT_NAMES = ('left_jaw_joint', 'right_jaw_joint', 'lift_joint', 'transport_joint')
_NAME_CHARS = set('abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_/')


class FrameError(GripperSimError):
    """A frame prefix or a result that cannot give a TF tree."""


def check_prefix(prefix: str) -> str:
    """``prefix`` if it is a valid frame prefix: '' or letters, digits, '_' and '/'
    (e.g. ``gripper1/``), not starting with '/' (tf2 frame ids have no leading slash)."""
    if not isinstance(prefix, str) or not set(prefix) <= _NAME_CHARS or \
            prefix.startswith('/') or '//' in prefix:
        raise FrameError(f"frame_prefix {prefix!r} is not valid: use letters, digits, '_' "
                         "and '/', without a leading '/' (e.g. 'gripper1/')")
    return prefix


@dataclass(frozen=True)
class GripperFrames:
    """Frame names and the fixed geometry the tree and the URDF need.

    Attributes:
        prefix: prepended to every gripper frame name ('' = none).
        left_outward: -1 when the left jaw sits at the smaller x (its joint opens
            towards -x), +1 otherwise.
        jaw_height, jaw_width, jaw_thickness: m, jaw plate size along z, y and x.
        max_gap: m, largest jaw gap (the jaw joints' upper limit is half of it).
        table_height: m, height of the table surface; None = no table.
        lift_range, transport_range: m, (lowest, highest) lift height and transport x
            the simulation accepts (``core.gripper.lift_range``, ``transport_range``):
            the URDF's joint limits.
        plate: the left jaw's plate in its jaw frame, ((x, z) of its centre, (x, z)
            size), m, x towards the fruit (the URDF's jaw box;
            ``finger_markers.JawPlate``, which ``MessageContext.from_config`` gives:
            a Fin Ray's lies on its base, above the finger). None: ``jaw_thickness``
            behind the jaw face over ``jaw_height``, a flat finger's.
    """

    prefix: str = ''
    left_outward: float = -1.0
    jaw_height: float = 0.04
    jaw_width: float = 0.04
    jaw_thickness: float = 0.01
    max_gap: float = 0.2
    table_height: float | None = 0.0
    lift_range: tuple[float, float] = (-FREE_TRAVEL, FREE_TRAVEL)
    transport_range: tuple[float, float] = (-FREE_TRAVEL, FREE_TRAVEL)
    plate: tuple[tuple[float, float], tuple[float, float]] | None = None

    def __post_init__(self) -> None:
        check_prefix(self.prefix)
        if self.left_outward not in (-1.0, 1.0):
            raise FrameError(f'left_outward must be -1 or +1, got {self.left_outward!r}')

    @classmethod
    def from_config(cls, config: Mapping[str, Any], *, prefix: str = '',
                    left_outward: float = -1.0) -> GripperFrames:
        """From the flat configuration (``configuration.load_config``)."""
        return cls(prefix=prefix, left_outward=left_outward,
                   jaw_height=float(config['gripper.jaw_height']),
                   jaw_width=float(config['gripper.jaw_width']),
                   jaw_thickness=float(config['gripper.jaw_thickness']),
                   max_gap=float(config['gripper.max_gap']),
                   table_height=float(config['world.table_height'])
                   if config['world.table'] else None,
                   lift_range=lift_range(config), transport_range=transport_range(config))

    def name(self, frame: str) -> str:
        """The full name of a gripper frame, e.g. ``g1/left_jaw``."""
        return self.prefix + frame

    @property
    def scene(self) -> str:
        """The frame of the fruit, the markers and the table: ``<p>world``, or ``world``
        itself without a prefix."""
        return self.name(WORLD_FRAME)

    @property
    def carriage(self) -> str:
        return self.name('carriage')

    @property
    def base(self) -> str:
        return self.name('gripper_base')

    @property
    def left_jaw(self) -> str:
        return self.name('left_jaw')

    @property
    def right_jaw(self) -> str:
        return self.name('right_jaw')

    @property
    def table(self) -> str:
        return self.name('table')

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints, named as on ``/joint_states`` (no prefix: each gripper publishes
        its own ``joint_states`` in its namespace; robot_state_publisher's
        ``frame_prefix`` likewise prefixes frames only)."""
        return JOINT_NAMES


@dataclass(frozen=True)
class FrameTransform:
    """One TF edge: ``child`` placed in ``parent``.

    Attributes:
        translation: (x, y, z) m.  rotation: (x, y, z, w) unit quaternion.
    """

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float] = IDENTITY


def joint_positions(result: Any, frames: GripperFrames) -> dict[str, float]:
    """Joint name -> position (m): jaws from the gripper centre (open > 0), lift, transport.

    ``result``: a ``StepResult`` (2D or 3D): ``left_jaw_x``, ``right_jaw_x``, ``lift``,
    ``gripper_x``.

    Raises:
        FrameError: a non-finite coordinate.
    """
    values = {'left_jaw_x': result.left_jaw_x, 'right_jaw_x': result.right_jaw_x,
              'lift': result.lift, 'gripper_x': result.gripper_x}
    bad = [k for k, v in values.items() if not abs(float(v)) < float('inf')]
    if bad:
        raise FrameError(f"result has non-finite {', '.join(bad)}: no TF for it")
    centre = float(result.gripper_x)
    left = (float(result.left_jaw_x) - centre) * frames.left_outward
    right = (float(result.right_jaw_x) - centre) * -frames.left_outward
    names = frames.joint_names
    return {names[0]: left, names[1]: right, names[2]: float(result.lift),
            names[3]: centre}


def dynamic_transforms(result: Any, frames: GripperFrames) -> list[FrameTransform]:
    """The moving edges of the tree (for ``/tf``), parents before children."""
    q = joint_positions(result, frames)
    left, right, lift, x = (q[n] for n in frames.joint_names)
    return [
        FrameTransform(WORLD_FRAME, frames.carriage, (x, 0.0, 0.0)),
        FrameTransform(frames.carriage, frames.base, (0.0, 0.0, lift)),
        FrameTransform(frames.base, frames.left_jaw, (frames.left_outward * left, 0.0, 0.0)),
        FrameTransform(frames.base, frames.right_jaw,
                       (-frames.left_outward * right, 0.0, 0.0)),
    ]


def static_transforms(frames: GripperFrames) -> list[FrameTransform]:
    """The fixed edges (for ``/tf_static``): the prefixed scene frame (with a prefix)
    and the table surface (when there is a table)."""
    edges = []
    if frames.scene != WORLD_FRAME:
        edges.append(FrameTransform(WORLD_FRAME, frames.scene, (0.0, 0.0, 0.0)))
    if frames.table_height is not None:
        edges.append(FrameTransform(WORLD_FRAME, frames.table,
                                    (0.0, 0.0, frames.table_height)))
    return edges


def frame_position(transforms: list[FrameTransform], frame: str) -> tuple[float, ...]:
    """The origin of ``frame`` in ``world`` (m), composing ``transforms`` (pure
    translations) up to the root; raises FrameError if the chain does not reach it."""
    parents = {t.child: t for t in transforms}
    position = [0.0, 0.0, 0.0]
    seen = set()
    while frame != WORLD_FRAME:
        edge = parents.get(frame)
        if edge is None or frame in seen:
            raise FrameError(f"frame '{frame}' is not connected to '{WORLD_FRAME}'")
        seen.add(frame)
        position = [p + t for p, t in zip(position, edge.translation)]
        frame = edge.parent
    return tuple(position)
