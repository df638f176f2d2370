"""The physics core: fruit models, energies, contact, time stepping. Knows nothing of ROS."""


def make_simulation(config, **kwargs):
    """The simulation the configuration asks for: 2D (``Simulation``) or, with
    ``dimension: 3``, 3D (``gripper_sim.core3d.simulation.Simulation3D``).

    ``kwargs`` go to the 2D ``Simulation`` (e.g. ``fast``); the 3D one takes none.
    """
    if int(config.get('dimension', 2)) == 3:
        from gripper_sim.core3d.simulation import Simulation3D
        if kwargs.get('fast'):
            from gripper_sim.errors import ConfigError
            raise ConfigError("the fast path is 2D only (config key 'dimension' is 3)")
        return Simulation3D(config)
    from gripper_sim.core.simulation import Simulation
    return Simulation(config, **kwargs)
