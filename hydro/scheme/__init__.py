"""The directionally split Godunov scheme: the sweep kernels, reconstruction, the HLLC face
solver and the CFL time step."""
