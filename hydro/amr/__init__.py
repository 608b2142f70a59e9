"""Adaptive mesh refinement of the block mesh (docs/hydro.md, "Adaptive mesh").

``regrid`` decides the leaf blocks and moves the state onto them, ``criteria`` says where the
mesh refines, ``plans`` indexes the coarse/fine faces of a mesh, ``transfer`` holds the
numba kernels that restrict, prolong and reflux across them and ``subcycle`` steps each level
with its own time step (``time_stepping = "per_level"``).
"""
