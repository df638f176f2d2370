"""The physics core: fruit models, energies, contact, time stepping. Knows nothing of ROS.

The 2D and 3D simulations are built by ``gripper_sim.workflows.factory.make_simulation``.
"""
