"""When a grasp slipped: the one definition shared by the grasp state machine (the node's
Grasp action result, ``pick``) and the analysis of a recording (``analyze``)."""
from __future__ import annotations

#: slip (m) of the fruit relative to the jaws beyond which the grasp slipped
SLIP_TOLERANCE = 1e-3


def grasp_slipped(held_slip: float, dropped: bool = False) -> bool:
    """Whether a grasp slipped.

    Args:
        held_slip: m, the fruit's slip relative to the jaws (``StepResult.slip_distance``,
            ``FruitState.slip_distance``) at the end of the hold: measured from the
            lift-off, or from the grip when there is no lift. Pushes of one jaw before
            the grip and the fruit's motion during a release do not count.
        dropped: no jaw touched the fruit at some time between the lift-off (or the
            grip) and the end of the hold.
    """
    return bool(dropped) or held_slip > SLIP_TOLERANCE
