"""The physics core: fruit models, energies, contact, time stepping. Knows nothing of ROS."""
