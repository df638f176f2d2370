"""Energies of the fruit and of soft fingers. Each has ``value``, ``gradient`` and
``hessian`` of the flat position vector q = [x0, z0, x1, z1, ...] (m), in J, N and N/m;
``evaluate`` returns all three at once. Hessians are IJV triplets ``(rows, cols, vals)``
to be summed into a sparse matrix; an energy may add rank-one terms ``(c, u)`` meaning
``c * u u^T``. Each energy has one implementation, its numba kernel (``kernels``, run by
``evaluate_into``); ``KernelEnergy`` builds ``evaluate`` on it.
"""
from gripper_sim.core.energies.base import Energy, Evaluation, KernelEnergy
from gripper_sim.core.energies.bending import RingBending, RodBending
from gripper_sim.core.energies.gravity import ConstantForce, Gravity
from gripper_sim.core.energies.neohookean import NeoHookeanTriangles
from gripper_sim.core.energies.pressure import EnclosedAreaPressure
from gripper_sim.core.energies.stretching import Stretching

__all__ = ['Energy', 'Evaluation', 'KernelEnergy', 'RingBending', 'RodBending', 'ConstantForce',
           'Gravity', 'NeoHookeanTriangles', 'EnclosedAreaPressure', 'Stretching']
