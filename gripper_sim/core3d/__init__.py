"""The 3D fruit and gripper: meshes, shell and tetrahedral energies, 3D contact.

Coordinates are (x, y, z): x the jaw closing axis, z up, y along the jaw faces.
Flat position vectors are q = [x0, y0, z0, x1, ...] (m). It reuses the 2D core's
stepper (``PatternCachingSolver(dim=3)``), contact bookkeeping and gripper kinematics.
"""
