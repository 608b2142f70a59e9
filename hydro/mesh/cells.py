"""Cell index arithmetic shared by the kernels that read a cell's neighbours along an axis."""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def shifted_cell(ix, iy, iz, d, k):
    """The padded cell index ``k`` steps from (ix, iy, iz) along axis ``d`` (0, 1 or 2)."""
    if d == 0:
        return ix + k, iy, iz
    if d == 1:
        return ix, iy + k, iz
    return ix, iy, iz + k
