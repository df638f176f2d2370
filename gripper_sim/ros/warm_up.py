"""The node's kernel warm-up: numba's kernels compiled (or loaded) before the node serves.

numba compiles a kernel at its first call, or loads it from its on-disk cache (``make
install`` fills it). Left to the first step, that call happens in the physics thread
under the simulation lock, after the node has advertised its services and actions: with
a cold cache the first step took ~95 s of CPU (2D apple), and every ``~/pause``,
``~/reset``, parameter change and goal waited for it. ``warm_kernels`` makes those calls
on a throw-away simulation of the same configuration instead, before the node creates
its interfaces: its jaws close at ``gripper.max_speed`` until they touch the fruit, so
the contact kernels (first called at the first contact) are ready too. From the cache
this takes well under a second (2D).
"""
from __future__ import annotations

import time
from typing import Any, Mapping

from gripper_sim.errors import ConvergenceError
from gripper_sim.workflows.factory import make_simulation

#: N, the throw-away grip: small, any fruit takes it
WARM_FORCE = 1.0
#: steps after the first contact (force control, the grip's own kernels)
STEPS_IN_CONTACT = 5
#: steps at most, whatever happens (the jaws meet the fruit after ~50 steps by default)
MAX_STEPS = 2000

# Configurations warmed in this process: numba compiles a kernel once per process.
_warmed: set[str] = set()


def warm_kernels(config: Mapping[str, Any]) -> float:
    """Call every kernel a grasp on ``config`` (flat configuration) uses, on a throw-away
    simulation: build it, close its jaws on the fruit with ``WARM_FORCE``, take
    ``STEPS_IN_CONTACT`` more steps. Nothing is published, the caller's simulation is
    not touched. A configuration warmed before in this process is not warmed again.

    Returns:
        Wall seconds taken (0 when already warm in this process).

    Raises:
        GripperSimError: the configuration cannot be simulated (not expected: the
            node built its own simulation of it). A step that does not converge is no
            error: the kernels it called are compiled all the same.
    """
    key = repr(sorted(config.items()))
    if key in _warmed:
        return 0.0
    start = time.perf_counter()
    sim = make_simulation(dict(config))
    sim.command_force(WARM_FORCE, float(config['gripper.max_speed']))
    touched = None
    try:
        for step in range(MAX_STEPS):
            if sim.step().grip_force > 0.0 and touched is None:
                touched = step
            if touched is not None and step >= touched + STEPS_IN_CONTACT:
                break
    except ConvergenceError:
        pass   # the kernels called so far are compiled; the node's own steps will tell
    _warmed.add(key)
    return time.perf_counter() - start
