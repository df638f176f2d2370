"""Compile every numba kernel once into numba's on-disk cache, at install time.

``python -m gripper_sim.workflows.compile_kernels`` (``make install`` runs it) closes the
jaws on small fruits in every route (``close_on_fruit``; ``warm_kernels`` does it for one
configuration, the ROS node's before it serves), so that no user pays numba's compile
time on a first run (a cold compile takes ~15-20 s of CPU in 2D, ~30 s in 3D): in 2D a
shell, a point fruit, a solid with a V-groove finger, a shell with a soft pad, one
between Fin Ray fingers, one between solid pads (without it a node's first solid-pad
start compiled for 67 s under load) and one with the barrier contact on flat fingers
(the whole-step kernel and the multi-step advance around it, the energy kernels, the
solver's and the barrier's, the compiled barrier Newton solve with one barrier (flat
fingers) and with two (the Fin Ray fingers' self-contact too): ``core.barrier_newton``,
~15 s cold); in 3D shells with a plain and a wrinkling skin, solids of linear and of
quadratic tetrahedra, and the default shell with the barrier contact on flat fingers,
between solid pads and between Fin Ray fingers (a first 3D solid-pad step compiled ~14 s
of kernels before they were here).
"""
from __future__ import annotations

import time
from typing import Any, Iterable, Mapping, Sequence

from gripper_sim.configuration import load_config
from gripper_sim.core.multistep import StopRules
from gripper_sim.errors import ConvergenceError
from gripper_sim.workflows.factory import make_simulation

#: N, the grip a warm-up closes with: small, any fruit takes it
WARM_FORCE = 1.0
#: steps after the first contact (force control, the grip's own kernels)
STEPS_IN_CONTACT = 5
#: steps at most, whatever happens (the jaws meet the fruit after ~50 steps by default)
MAX_STEPS = 2000

#: ``--set`` overrides of the small 2D set-ups that together reach every 2D kernel
SETUPS_2D = (('fruit.model=shell', 'fruit.nodes=16'),
             ('fruit.model=point', 'fruit.nodes=16'),
             ('fruit.model=solid', 'gripper.finger.type=vgroove', 'fruit.nodes=16'),
             ('fruit.model=shell', 'gripper.finger.pad.enabled=true', 'fruit.nodes=16'),
             ('fruit.model=shell', 'gripper.finger.type=fin_ray', 'fruit.nodes=16'),
             ('fruit.model=shell', 'gripper.finger.type=solid_pad', 'fruit.nodes=16'),
             ('fruit.model=shell', 'contact.model=ipc', 'fruit.nodes=16'))

_SMALL_3D = ('dimension=3', 'fruit.mesh.subdivisions=3')
#: ``--set`` overrides of the small 3D set-ups that together reach every 3D kernel
SETUPS_3D = (_SMALL_3D + ('fruit.model=shell', 'fruit.pressure.turgor=2e4'),
             _SMALL_3D + ('fruit.model=shell', 'fruit.pressure.turgor=2e4',
                          'fruit.skin.wrinkling=true'),
             _SMALL_3D + ('fruit.model=solid', 'fruit.mesh.max_tet_volume=1e-6'),
             _SMALL_3D + ('fruit.model=solid', 'fruit.mesh.max_tet_volume=1e-6',
                          'fruit.mesh.order=2'),
             _SMALL_3D + ('contact.model=ipc',),
             _SMALL_3D + ('gripper.finger.type=solid_pad',),
             _SMALL_3D + ('gripper.finger.type=fin_ray',))


def close_on_fruit(sim, speed: float) -> None:
    """Close the jaws of ``sim`` on its fruit with ``WARM_FORCE`` at ``speed`` (m/s) until
    they touch it, then ``STEPS_IN_CONTACT`` steps more (``MAX_STEPS`` at most): every
    kernel a grasp's steps call is called, those first called at the first contact too.
    A step that does not converge ends it: the kernels it called are compiled all the
    same."""
    sim.command_force(WARM_FORCE, speed)
    touched = None
    try:
        for step in range(MAX_STEPS):
            result = sim.step()
            result.slipping  # read, as the node reads it: slip.surface_motion compiled too
            if result.grip_force > 0.0 and touched is None:
                touched = step
            if touched is not None and step >= touched + STEPS_IN_CONTACT:
                return
    except ConvergenceError:
        pass


def warm_cache(setups: Iterable[Sequence[str]]) -> float:
    """Close each set-up (its ``--set`` overrides) on its fruit (``close_on_fruit``), then
    three more steps in one ``advance`` where the set-up has it; wall seconds taken."""
    start = time.perf_counter()
    for overrides in setups:
        config = load_config(overrides=list(overrides))
        sim = make_simulation(config)
        close_on_fruit(sim, float(config['gripper.max_speed']))
        sim.advance(StopRules(max_steps=3))
    return time.perf_counter() - start


#: the configurations ``warm_kernels`` warmed in this process (numba loads or compiles a
#: kernel once per process)
_warmed: set[str] = set()


def warm_kernels(config: Mapping[str, Any]) -> float:
    """Load from numba's cache, or compile, every kernel a grasp on ``config`` (flat
    configuration) calls, on a throw-away simulation closed on its fruit
    (``close_on_fruit``); the caller's simulations are not touched. A configuration
    warmed before in this process is not warmed again. The ROS node does this before it
    offers any interface: left to its first step, a cold compile (~95 s of CPU for the
    2D apple) held the simulation lock while its services and goals waited.

    Returns:
        Wall seconds taken (0 when already warm in this process).

    Raises:
        GripperSimError: the configuration cannot be simulated.
    """
    key = repr(sorted(config.items()))
    if key in _warmed:
        return 0.0
    start = time.perf_counter()
    close_on_fruit(make_simulation(dict(config)), float(config['gripper.max_speed']))
    _warmed.add(key)
    return time.perf_counter() - start


def main() -> int:
    print(f'2D kernels compiled and cached in {warm_cache(SETUPS_2D):.1f} s')
    print(f'3D kernels compiled and cached in {warm_cache(SETUPS_3D):.1f} s')
    return 0


if __name__ == '__main__':  # pragma: no cover - install-time helper
    raise SystemExit(main())
