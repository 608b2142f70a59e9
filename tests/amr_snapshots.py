"""Multi-level snapshots for the viewer tests: hand-made leaf sets and refined real snapshots."""

import h5py
import numpy as np

from impactpipe.hydro import PROBLEMS, append_snapshot
from impactpipe.hydro.output.snapshot import GEOMETRY_DIMENSIONS, Snapshot

GAS = {"gas": {"eos": {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}}}

#: (geometry, root blocks per used axis, blocks to refine as (level, i, j, k), in order)
LEAF_SETS = {
    "1d-planar": ((3,), [(0, 1, 0, 0), (1, 3, 0, 0)]),
    "2d-planar": ((2, 2), [(0, 1, 1, 0)]),
    "2d-cylindrical": ((2, 3), [(0, 0, 1, 0), (1, 1, 2, 0), (0, 1, 2, 0)]),
    "3d": ((2, 1, 2), [(0, 1, 0, 1), (1, 2, 1, 3)]),
}


def children(key, ndim):
    """The 2^ndim child keys of block ``key`` = (level, i, j, k)."""
    level, *index = key
    return [(level + 1, *(2 * i + o for i, o in zip(index, offset)))
            for offset in np.ndindex(*(2 if d < ndim else 1 for d in range(3)))]


def leaf_keys(ndim, root_blocks, refine):
    """Leaves of the root grid after splitting the blocks of ``refine`` one after the other."""
    root = [root_blocks[d] if d < ndim else 1 for d in range(3)]
    leaves = {(0, *ix) for ix in np.ndindex(*root)}
    for key in refine:
        leaves.remove(key)
        leaves.update(children(key, ndim))
    return sorted(leaves)


def handmade_snapshot(geometry, cells=4, root_size=1.0, seed=0):
    """A snapshot of the leaf set :data:`LEAF_SETS` [geometry] with random cell values, two
    materials ("basalt" and "basalt (projectile)"), an empty block, and a ``damage`` extra."""
    ndim = GEOMETRY_DIMENSIONS[geometry]
    root_blocks, refine = LEAF_SETS[geometry]
    keys = leaf_keys(ndim, root_blocks, refine)
    nb = len(keys)
    shape = tuple(cells if d < ndim else 1 for d in range(3))
    level = np.array([k[0] for k in keys])
    index = np.array([k[1:] for k in keys])
    used = np.arange(3) < ndim
    size = root_size / 2.0 ** level[:, None]
    lo = np.where(used, index * size, 0.0)
    hi = np.where(used, lo + size, 0.0)
    rng = np.random.default_rng(seed)
    alpha = rng.random((nb, 2) + shape) / 2
    arho = alpha * np.array([2700.0, 3000.0])[None, :, None, None, None] * (1 + 0.1 * rng.random((nb, 2) + shape))
    finest = int(np.argmax(level))
    alpha[finest] = 0.0  # an empty (void) block among the finest
    arho[finest] = 0.0
    velocity = rng.normal(size=(nb, 3) + shape) * 100.0
    velocity[:, ndim if geometry != "2d-cylindrical" else 2:] = 0.0
    return Snapshot(time=1.25, geometry=geometry, material_names=["basalt", "basalt (projectile)"],
                    block_lo=lo, block_hi=hi, block_level=level, block_id=np.arange(nb) + 100,
                    partial_density=arho, volume_fraction=alpha, velocity=velocity,
                    specific_internal_energy=rng.random((nb,) + shape) * 1e5,
                    pressure=rng.random((nb,) + shape) * 1e9, temperature=300.0 + rng.random((nb,) + shape),
                    sound_speed=3000.0 + rng.random((nb,) + shape), extra={"damage": rng.random((nb,) + shape)})


def refine_block(snapshot, b):
    """``snapshot`` with block ``b`` replaced by its 2^ndim children, each child cell holding
    the values of the parent cell it lies in (mass, momentum and energy are unchanged)."""
    ndim = snapshot.ndim
    shape = snapshot.cells_per_block
    used = np.arange(3) < ndim
    lo, hi = snapshot.block_lo[b], snapshot.block_hi[b]
    half = np.where(used, (hi - lo) / 2, 0.0)
    kids = list(np.ndindex(*(2 if u else 1 for u in used)))

    def fine(values):
        """Child blocks of one block-shaped array (..., nx, ny, nz) by injection."""
        out = []
        for offset in kids:
            coarse = values[(...,) + tuple(slice(o * n // 2, (o + 1) * n // 2) if u else slice(None)
                                           for o, n, u in zip(offset, shape, used))]
            for axis, u in enumerate(used):
                if u:
                    coarse = np.repeat(coarse, 2, axis=coarse.ndim - 3 + axis)
            out.append(coarse)
        return np.stack(out)

    def replace(array):
        return np.concatenate([np.delete(array, b, axis=0), fine(array[b])])

    offsets = np.array(kids, dtype=float)
    return Snapshot(
        time=snapshot.time, geometry=snapshot.geometry, material_names=snapshot.material_names,
        block_lo=np.concatenate([np.delete(snapshot.block_lo, b, axis=0), lo + offsets * half]),
        block_hi=np.concatenate([np.delete(snapshot.block_hi, b, axis=0), lo + (offsets + 1) * half]),
        block_level=np.concatenate([np.delete(snapshot.block_level, b),
                                    np.full(len(kids), snapshot.block_level[b] + 1)]),
        block_id=np.concatenate([np.delete(snapshot.block_id, b), snapshot.block_id.max() + 1 + np.arange(len(kids))]),
        **{name: replace(getattr(snapshot, name)) for name in (
            "partial_density", "volume_fraction", "velocity", "specific_internal_energy", "pressure",
            "temperature", "sound_speed")},
        extra={name: replace(values) for name, values in snapshot.extra.items()},
    )


def sedov_run(run_dir, cells=32, output_times=(0.005, 0.01, 0.02)):
    """A run directory whose hydro.h5 holds the snapshots of a 2d-cylindrical Sedov run."""
    run_dir.mkdir(parents=True, exist_ok=True)
    sim = PROBLEMS["sedov"].setup({"cells": cells}, GAS, geometry="2d-cylindrical")
    snapshots = []

    def write(snapshot):
        snapshots.append(snapshot)
        with h5py.File(run_dir / "hydro.h5", "a") as fh:
            append_snapshot(fh, snapshot)

    sim.run(output_times[-1], output_times=output_times, on_output=write)
    return snapshots
