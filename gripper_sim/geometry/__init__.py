"""Plane geometry that the configuration describes, below the configuration and the physics.

``shapes``: fruit outlines (circle, ellipse, egg, spline, polygon) and their checks;
``fingers``: the jaw face profiles (flat, V-groove, arc) as flat facets. Both read
configuration values from a mapping and import only numpy and ``gripper_sim.errors``, so
that the configuration can validate an outline or a finger without the physics.
"""
