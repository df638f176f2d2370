"""What the 3D energies share: dof indices, and the triplet form of their kernels.

Every 3D energy is computed by one numba kernel (``gripper_sim.core3d.kernels``), which
its ``evaluate_into`` runs; ``KernelEnergy`` (``gripper_sim.core.energies.base``, the
same for 2D and 3D) gives it the ``Energy.evaluate`` protocol (IJV triplets). The numpy
references the kernels are tested against live in ``test/reference_energies3d.py``.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import KernelEnergy, element_dofs

__all__ = ['KernelEnergy', 'element_dofs3']


def element_dofs3(nodes: np.ndarray) -> np.ndarray:
    """(n_elem, k) node indices to (n_elem, 3k) dof indices [x, y, z] per node."""
    return element_dofs(nodes, 3)
