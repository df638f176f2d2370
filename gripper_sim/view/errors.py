"""The one error class of the view subpackage."""
from __future__ import annotations

from gripper_sim.errors import GripperSimError


class ViewError(GripperSimError):
    """The live view cannot start (e.g. its port is taken); the message says what to do."""
