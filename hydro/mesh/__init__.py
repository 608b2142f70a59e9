"""The block mesh, the conserved multi-material state on it, and its ghost layers."""
