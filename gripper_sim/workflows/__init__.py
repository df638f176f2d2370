"""Workflows over the physics core: studies and calibration (no ROS)."""
