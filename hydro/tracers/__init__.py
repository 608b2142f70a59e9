"""Massless Lagrangian tracers: their motion with the material and their peak-pressure records."""
