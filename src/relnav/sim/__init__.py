"""Simulation: targets, sensors, trajectories, attitude, scenarios and presets."""
