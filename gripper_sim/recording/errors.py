"""The one error class of the recording subpackage."""
from __future__ import annotations

from gripper_sim.errors import GripperSimError


class RecordingError(GripperSimError):
    """A recording cannot be written, read, replayed, recovered or analysed.

    The message names the file or topic at fault and, where there is one, what to do.
    """
