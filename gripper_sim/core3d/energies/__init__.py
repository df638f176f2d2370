"""Energies of the 3D fruit, on the flat position vector q = [x0, y0, z0, x1, ...] (m).

Same protocol as the 2D energies (``gripper_sim.core.energies.base.Energy``): value
(J), gradient (N) and Hessian IJV triplets (N/m), plus optional rank-one terms.
"""
from gripper_sim.core3d.energies.hinge import HingeBending, dihedral_angles
from gripper_sim.core3d.energies.membrane import Membrane
from gripper_sim.core3d.energies.neohookean import NeoHookeanTets
from gripper_sim.core3d.energies.pressure import EnclosedVolumePressure

__all__ = ['HingeBending', 'dihedral_angles', 'Membrane', 'NeoHookeanTets',
           'EnclosedVolumePressure']
