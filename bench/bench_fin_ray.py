"""Benchmark of the Fin Ray finger against the rigid flat finger: CPU time of a 2D
grasp-and-lift of the default apple. Prints figures; asserts nothing.

The same grasp as ``bench_soft_fingers.py`` (the jaws 1 mm from where the fingers touch
the apple, force mode to ``--force`` N, lifted 1 cm, held 0.2 s, dt = 1 ms), CPU time of
this process (``time.process_time``, the best of ``--repeat`` runs; the load average is
printed), side by side for ``gripper.finger.type`` flat and fin_ray; ``--set KEY=VALUE``
(the Fin Ray's grasp only), ``--reference-set KEY=VALUE`` (the flat finger's only:
``contact.model=ipc`` compares the two fingers on the same contact model) and
``--baseline DIR`` as there (another checkout's runs alternated with this one's).

Usage::

    nice python bench/bench_fin_ray.py [--repeat N] [--force N] [--set KEY=VALUE]
        [--reference-set KEY=VALUE] [--baseline DIR]
"""
from __future__ import annotations

import sys

from bench_soft_fingers import compare


def main(argv=None) -> int:
    return compare(('flat', 'fin_ray'), __doc__.splitlines()[0], argv)


if __name__ == '__main__':
    sys.exit(main())
