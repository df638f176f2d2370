"""Compile every numba kernel once into numba's on-disk cache, at install time.

``python -m gripper_sim.workflows.compile_kernels`` (``make install`` runs it) steps small
fruits in every route, so that no user pays numba's compile time on a first run (a cold
compile takes ~15-20 s of CPU in 2D, ~30 s in 3D): in 2D a shell, a point fruit, a
solid with a V-groove finger, a shell with a soft pad, one between Fin Ray fingers, one
between solid pads (without it a node's first solid-pad start compiled for 67 s under
load) and one with the barrier contact on flat fingers (the whole-step kernel and the
multi-step advance around it, the energy kernels, the solver's and the barrier's, the
compiled barrier Newton solve with one barrier (flat fingers) and with two (the Fin Ray
fingers' self-contact too): ``core.barrier_newton``, ~15 s cold); in 3D
shells with a plain and a wrinkling skin, solids of linear and of quadratic
tetrahedra, and the default shell with the barrier contact on flat fingers, between
solid pads and between Fin Ray fingers (a first 3D solid-pad step compiled ~14 s of
kernels before they were here).
"""
from __future__ import annotations

import time
from typing import Iterable, Sequence

from gripper_sim.configuration import load_config
from gripper_sim.core.multistep import StopRules
from gripper_sim.workflows.factory import make_simulation

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


def warm_cache(setups: Iterable[Sequence[str]]) -> float:
    """Step each set-up (its ``--set`` overrides) three times at 1 N, then three more in
    one ``advance`` where the set-up has it; wall seconds taken."""
    start = time.perf_counter()
    for overrides in setups:
        sim = make_simulation(load_config(overrides=list(overrides)))
        sim.command_force(1.0)
        for _ in range(3):
            sim.step()
        sim.advance(StopRules(max_steps=3))
    return time.perf_counter() - start


def main() -> int:
    print(f'2D kernels compiled and cached in {warm_cache(SETUPS_2D):.1f} s')
    print(f'3D kernels compiled and cached in {warm_cache(SETUPS_3D):.1f} s')
    return 0


if __name__ == '__main__':  # pragma: no cover - install-time helper
    raise SystemExit(main())
