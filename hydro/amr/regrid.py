"""Regridding: choose the new leaf blocks (2:1 balanced) and move the state onto them.

Every ``interval`` steps :func:`regrid` evaluates the refinement indicators
(:mod:`impactpipe.hydro.amr.criteria`) and

1. flags blocks to refine (an indicator above its threshold, a user box asking for a finer
   level; only below ``max_level``) and blocks that may coarsen (every indicator below half
   its threshold, no box asking for their level);
2. keeps 2:1 balance across faces, edges and corners: a block to be refined forces its coarser
   neighbours to refine too (repeated until nothing changes); a complete group of 2^ndim
   sibling leaves coarsens only if all may and its parent would stay within one level of
   every neighbour (groups are taken finest level first, each decision seen by the next);
3. builds the new mesh and fills it: kept blocks are copied, new children prolonged
   conservatively from their parent, new parents restricted from their children
   (:mod:`impactpipe.hydro.amr.transfer`), so mass, momentum and energy are unchanged to
   round-off.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from impactpipe.hydro.amr.criteria import (
    IND_DENSITY,
    IND_INTERFACE,
    IND_MAX_PRESSURE,
    IND_MAX_SPEED,
    IND_PRESSURE,
    INTERFACE_JUMP,
    NINDICATOR,
    block_indicators,
    box_levels,
    mixture_pressure,
)
from impactpipe.hydro.amr.plans import axis0_weights
from impactpipe.hydro.amr.transfer import prolong_blocks, restrict_blocks
from impactpipe.hydro.mesh.blocks import BlockMesh, morton_keys
from impactpipe.hydro.mesh.last_good import NONE_KNOWN, void_blocks
from impactpipe.hydro.mesh.state import FIELDS, HydroState


#: Values of :attr:`RefinementRule.interfaces`.
INTERFACE_MODES = ("all", "active", "off")
#: Values of :attr:`RefinementRule.buffer`.
BUFFER_MODES = ("block", "reach")


@dataclass(frozen=True)
class RefinementRule:
    """When and where the mesh refines (``hydro.refinement`` in the config).

    Attributes:
        interval: steps between regrids.
        interfaces: where a material interface or free surface crossing a block refines it:
            "all" (to the finest level), "active" (to the finest level where the block moves
            or is loaded, :mod:`impactpipe.hydro.amr.criteria`, one level coarser where it is
            quiet) or "off".
        pressure_jump: refine where the relative pressure jump across a cell exceeds this
            (None: off); see :mod:`impactpipe.hydro.amr.criteria`.
        density_jump: the same for density (None: off).
        pressure_floor: p_floor of the pressure indicator (and, unless ``activity_floor`` is
            given, the activity threshold of ``interfaces: active``) as a fraction of the
            largest |p| on the mesh so far.
        activity_floor: the activity threshold of ``interfaces: active`` as a fraction of the
            largest |p| on the mesh so far and of the largest speed on the mesh now (None:
            ``pressure_floor``).
        buffer: which neighbours of a block with a pressure or density jump refine with it:
            "block" (every neighbour across its faces, edges and corners) or "reach" (those
            across the faces, edges and corners the jump lies within ``reach`` cells of: the
            cells a wave crosses between two regrids, :func:`block_wants`).
        boxes: ((lo, hi, level), ...): refine every block overlapping [lo, hi] (m) to at
            least ``level``.
        material_depth: keep every block holding material within this many levels of the
            finest (None: no limit): the interior of a body may coarsen behind a shock, but
            not further than this (docs/performance.md, "Where the remnants differ").
    """

    interval: int = 4
    interfaces: str = "all"
    pressure_jump: float | None = 0.2
    density_jump: float | None = 0.1
    pressure_floor: float = 1.0e-3
    activity_floor: float | None = None
    buffer: str = "block"
    boxes: tuple = ()
    material_depth: int | None = None

    def __post_init__(self):
        if self.interval < 1:
            raise ValueError(f"refinement interval must be >= 1 step, got {self.interval}")
        if self.interfaces not in INTERFACE_MODES:
            raise ValueError(f"refinement interfaces must be one of {INTERFACE_MODES}, got {self.interfaces!r}")
        if self.buffer not in BUFFER_MODES:
            raise ValueError(f"refinement buffer must be one of {BUFFER_MODES}, got {self.buffer!r}")
        for name in ("pressure_jump", "density_jump"):
            value = getattr(self, name)
            if value is not None and not 0.0 < value < 1.0:
                raise ValueError(f"refinement {name} must lie in (0, 1) or be None, got {value}")
        if self.material_depth is not None and self.material_depth < 0:
            raise ValueError(f"refinement material_depth must be >= 0 levels or None, got {self.material_depth}")


@dataclass(frozen=True)
class BlockWants:
    """What the refinement rule asks of each block at one regrid (:func:`block_wants`).

    Attributes:
        indicators: (NB, NINDICATOR) the block indicators (:func:`~impactpipe.hydro.amr.criteria.block_indicators`).
        floor: p_floor (Pa) of the pressure indicator.
        active: (NB,) bool, the block moves or is loaded (``interfaces: active``; all True otherwise).
        shock: (NB,) the level the block's own pressure or density jump asks for (the finest or 0).
        shock_keep: (NB,) the same at half the thresholds (the level it may not coarsen below).
        face: (NB,) the level its interface asks for (the finest, one coarser where inactive, or 0).
        face_keep: (NB,) the same at half the interface threshold.
        boxes: (NB,) the finest level a user box asks for.
        material: (NB,) the level ``material_depth`` asks of a block holding material (0 elsewhere).
        want: (NB,) the level asked for: the jumps of the block and its neighbours, its interface.
        keep: (NB,) the level below which it may not coarsen, by the same rules at half the thresholds.
        peak_pressure: the largest |p| (Pa) of this and the earlier regrids.
    """

    indicators: np.ndarray
    floor: float
    active: np.ndarray
    shock: np.ndarray
    shock_keep: np.ndarray
    face: np.ndarray
    face_keep: np.ndarray
    boxes: np.ndarray
    material: np.ndarray
    want: np.ndarray
    keep: np.ndarray
    peak_pressure: float


def block_wants(mesh: BlockMesh, state: HydroState, eos, shear_modulus, tensile_strength,
                rule: RefinementRule, peak_pressure: float = 0.0,
                grady_kipp: np.ndarray | None = None,
                porosity: np.ndarray | None = None, reach: int | None = None, partition=None,
                late: np.ndarray | None = None, finish_fill: Callable[[], None] | None = None) -> BlockWants:
    """The levels the refinement rule asks of each block (:class:`BlockWants`; arguments as :func:`flag_blocks`).

    With ``buffer: reach`` a jump refines the neighbours across the faces, edges and corners
    of its block that it lies within ``reach`` cells of (an edge or corner neighbour when the
    block holds such a jump near each of the faces meeting there): a shock crosses at most
    cfl cells of its level per substep, so ``reach`` = ceil(cfl x finest substeps between
    regrids) + 1 (the indicators' stencil) keeps it inside refined blocks until the next
    regrid, and the blocks it has left may coarsen.  With ``buffer: block``, or ``reach``
    None, a jump refines every neighbour.

    ``partition`` (several MPI ranks, :mod:`impactpipe.hydro.parallel.distributed`), or None
    (one process): each process computes the pressure and the indicators of the blocks it
    advances (``partition.blocks``) only, the largest |p| is one reduction (MAX) and the
    indicator rows reach every process (``partition.share_rows``), so every process goes on
    from the same (NB, ...) indicators, the single process's bit for bit.

    ``finish_fill``: where the first ghost layer of the blocks ``late`` (int64 block numbers)
    is still being filled (the strips of other processes travelling,
    :meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.start_first_ghost_layer`), the call
    that completes it: the pressure of the other blocks is evaluated first, then, after it, that
    of the ``late`` blocks (each cell's pressure is its own state's, so the order changes no bit)."""
    lo, hi = (0, mesh.nblocks) if partition is None else partition.blocks.indices(mesh.nblocks)[:2]
    zeros = np.zeros if partition is None else partition.zeros
    fields = tuple(field.view(np.int64) for field in (state.alpha, state.arho, state.arhoe, state.momentum,
                                                      state.energy))
    void = np.ones(mesh.nblocks, dtype=np.uint8)  # the blocks of other processes are skipped as void
    void_blocks(*fields, lo, hi, void, NONE_KNOWN)
    pressure = zeros((mesh.nblocks,) + mesh.padded_shape)
    evaluate = void
    if finish_fill is not None:
        evaluate = void.copy()
        evaluate[late] = 1
    mixture_pressure(state.alpha, state.arho, state.arhoe, state.arhoq, eos.kind, eos.params, eos.table,
                     shear_modulus, tensile_strength, pressure, grady_kipp, porosity, evaluate)
    if finish_fill is not None:
        finish_fill()
        void_blocks(*fields, lo, hi, void, NONE_KNOWN)  # a late block's ghosts may hold material now, or none
        evaluate = np.ones_like(void)
        evaluate[late] = void[late]
        mixture_pressure(state.alpha, state.arho, state.arhoe, state.arhoq, eos.kind, eos.params, eos.table,
                         shear_modulus, tensile_strength, pressure, grady_kipp, porosity, evaluate)
    peak_pressure = max(peak_pressure, float(np.abs(mesh.interior(pressure)[lo:hi]).max(initial=0.0)))
    if partition is not None:
        peak_pressure = partition.largest(peak_pressure)
    floor = rule.pressure_floor * max(peak_pressure, 1e-300)
    ind = np.zeros((mesh.nblocks, NINDICATOR))
    near = np.zeros((mesh.nblocks, 3, 2, 2))
    margin = mesh.block_cells if reach is None or rule.buffer == "block" else int(reach)
    block_indicators(state.alpha, state.arho, state.momentum, pressure, mesh.ndim, floor, margin, ind, near, void)
    del pressure
    if partition is not None:
        partition.share_rows(ind)
        partition.share_rows(near)
    thresholds = np.full(IND_MAX_PRESSURE, np.inf)
    if rule.interfaces != "off":
        thresholds[IND_INTERFACE] = INTERFACE_JUMP
    if rule.pressure_jump is not None:
        thresholds[IND_PRESSURE] = rule.pressure_jump
    if rule.density_jump is not None:
        thresholds[IND_DENSITY] = rule.density_jump
    # the level each block's indicators ask for: the finest, or (a quiet interface under
    # "active") one level below it; keep: the level below which it may not coarsen
    finest = mesh.max_level
    active = np.ones(mesh.nblocks, dtype=bool)
    if rule.interfaces == "active":
        fraction = rule.pressure_floor if rule.activity_floor is None else rule.activity_floor
        speed_floor = fraction * ind[:, IND_MAX_SPEED].max(initial=0.0)
        active = ((ind[:, IND_MAX_PRESSURE] > fraction * max(peak_pressure, 1e-300))
                  | (ind[:, IND_MAX_SPEED] > speed_floor))
    interface_level = np.where(active, finest, max(finest - 1, 0))
    jumps = ind[:, :IND_MAX_PRESSURE]
    shock = np.where((jumps[:, 1:] > thresholds[1:]).any(axis=1), finest, 0)
    shock_keep = np.where((jumps[:, 1:] > 0.5 * thresholds[1:]).any(axis=1), finest, 0)
    face = np.where(jumps[:, IND_INTERFACE] > thresholds[IND_INTERFACE], interface_level, 0)
    face_keep = np.where(jumps[:, IND_INTERFACE] > 0.5 * thresholds[IND_INTERFACE], interface_level, 0)
    boxes = box_levels(mesh.block_lo, mesh.block_hi, mesh.ndim, rule.boxes)
    material = np.zeros(mesh.nblocks, dtype=np.int64)
    if rule.material_depth is not None:
        held = (void == 0).astype(np.float64)
        if partition is not None:
            partition.share_rows(held)
        material = np.where(held > 0.0, max(finest - rule.material_depth, 0), 0)
    if margin < mesh.block_cells:
        want = np.maximum(_with_reached_neighbours(mesh, shock, (near > thresholds[1:]).any(axis=3)), face)
        keep = np.maximum(_with_reached_neighbours(mesh, shock_keep, (near > 0.5 * thresholds[1:]).any(axis=3)),
                          face_keep)
    else:
        want = np.maximum(_with_neighbours(mesh, shock), face)
        keep = np.maximum(_with_neighbours(mesh, shock_keep), face_keep)
    want = np.maximum(want, material)
    keep = np.maximum(keep, material)
    return BlockWants(ind, floor, active, shock, shock_keep, face, face_keep, boxes, material, want, keep,
                      peak_pressure)


def flag_blocks(mesh: BlockMesh, state: HydroState, eos, shear_modulus, tensile_strength,
                rule: RefinementRule, peak_pressure: float = 0.0,
                grady_kipp: np.ndarray | None = None,
                porosity: np.ndarray | None = None, reach: int | None = None,
                partition=None, late: np.ndarray | None = None,
                finish_fill: Callable[[], None] | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(refine, coarsen) flags per block and the largest |p| seen so far (Pa).

    The state's first ghost layer along every used axis must be filled (the indicators look one
    cell beyond a block).  ``peak_pressure`` is the largest
    |p| of earlier regrids: the pressure floor is ``pressure_floor`` times the largest |p|
    ever on the mesh, so the waves left behind once the impact's shock has decayed (acoustic
    noise on the scale of the event) do not keep the whole body refined.  ``grady_kipp``: the
    materials bearing (1 - D) of their tension (:func:`impactpipe.hydro.scheme.mixture.tension_factor`);
    ``porosity``: the porous materials' rows (:func:`impactpipe.hydro.eos.porosity.pack_porosity`) or None.
    The pressure and indicators of the void blocks (ghosts included,
    :func:`~impactpipe.hydro.mesh.last_good.void_blocks`) are not computed: they are 0.
    ``reach``: the cells a wave crosses between two regrids plus one, for ``buffer: reach``
    (:func:`block_wants`).  ``partition``, ``late``, ``finish_fill``: as there (each process
    reads its own blocks; every process returns the same flags).
    """
    wants = block_wants(mesh, state, eos, shear_modulus, tensile_strength, rule, peak_pressure, grady_kipp,
                        porosity, reach, partition, late, finish_fill)
    level = mesh.block_level
    refine = ((wants.want > level) | (wants.boxes > level)) & (level < mesh.max_level)
    coarsen = (wants.keep < level) & (wants.boxes < level) & (level > 0)
    return refine, coarsen, wants.peak_pressure


def _with_neighbours(mesh: BlockMesh, levels: np.ndarray) -> np.ndarray:
    """The largest of ``levels`` over each block and its neighbours across faces, edges and corners.

    A buffer of one block around what the shock criteria ask for: a shock about to leave a
    refined block finds its next block refined before it arrives (the indicators only see
    one cell beyond a block, a regrid comes every few steps and a shock crosses up to
    ``cfl`` cells per step).  Interfaces move with the material, well under a cell between
    regrids, and get no buffer.  The maximum
    spreads axis by axis through the neighbour tables, so edges and corners are reached.
    """
    out = levels.copy()
    for d in range(mesh.ndim):
        spread = out.copy()
        for side in (0, 1):
            nbr = mesh.neighbor[:, d, side]
            inside = np.nonzero(nbr >= 0)[0]
            np.maximum.at(spread, nbr[inside], out[inside])
        out = spread
    return out


def _with_reached_neighbours(mesh: BlockMesh, levels: np.ndarray, near: np.ndarray) -> np.ndarray:
    """The largest of ``levels`` over each block and those neighbours whose faces ``near`` marks.

    ``near[b, d, side]`` (bool, (NB, 3, 2)): block b's jump lies close to its face (d, side);
    ``levels[b]`` then spreads to the neighbour across that face, and to the neighbour across
    an edge or corner where ``near`` marks every face meeting there.  Such a neighbour is
    reached through the face neighbour tables axis by axis, in every order of the axes (on a
    mesh with level changes the orders can end on different blocks; each gets the level).
    """
    out = levels.copy()
    for o in _offsets(mesh.ndim):
        steps = [(d, 0 if o[d] < 0 else 1) for d in range(mesh.ndim) if o[d]]
        mask = levels > 0
        for d, side in steps:
            mask &= near[:, d, side]
        source = np.nonzero(mask)[0]
        for order in itertools.permutations(steps):
            src, dst = source, source
            for d, side in order:
                dst = mesh.neighbor[dst, d, side]
                inside = dst >= 0
                src, dst = src[inside], dst[inside]
            np.maximum.at(out, dst, levels[src])
    return out


def _offsets(ndim: int) -> list[tuple]:
    """Neighbour offsets across faces, edges and corners of a block."""
    return [o + (0,) * (3 - ndim) for o in itertools.product((-1, 0, 1), repeat=ndim) if any(o)]


def _children(ndim: int) -> list[tuple]:
    """The (cx, cy, cz) positions of a block's 2^ndim children."""
    return [c + (0,) * (3 - ndim) for c in itertools.product((0, 1), repeat=ndim)]


class _Leaves:
    """The leaf set as a dict (level, i, j, k) -> old block index, with region queries."""

    def __init__(self, mesh: BlockMesh):
        self.mesh = mesh
        self.ndim = mesh.ndim
        self.periodic = [mesh.boundaries[d][0] == "periodic" if d < mesh.ndim else False for d in range(3)]
        self.leaf = {(lv, *ix): b for b, (lv, ix) in enumerate(zip(mesh.block_level.tolist(),
                                                                    mesh.block_index.tolist()))}
        #: per level, the blocks tiling the domain along each axis
        self.extent = mesh.blocks_at_level(np.arange(mesh.max_level + 1)).tolist()

    def region(self, level: int, index) -> tuple | None:
        """The block-grid region (level, i, j, k) wrapped periodically; None outside the domain."""
        extent = self.extent[level]
        out = []
        for d in range(3):
            i = int(index[d])
            if self.periodic[d]:
                i %= int(extent[d])
            elif not 0 <= i < extent[d]:
                return None
            out.append(i)
        return (level,) + tuple(out)

    def containing(self, key: tuple) -> tuple | None:
        """The leaf key containing region ``key`` (itself or an ancestor); None if it is subdivided."""
        level, *index = key
        while level >= 0:
            k = (level,) + tuple(index)
            if k in self.leaf:
                return k
            level -= 1
            index = [i >> 1 for i in index]
        return None


def plan_leaves(mesh: BlockMesh, refine: np.ndarray, coarsen: np.ndarray) -> dict | None:
    """The new leaf set from the flags, 2:1 balanced (module docstring); None when nothing changes.

    Returns a dict with ``level`` and ``index`` of the new leaves (in Morton order,
    :func:`~impactpipe.hydro.mesh.blocks.morton_keys`),
    ``keep`` (new, old) index pairs, ``children`` rows (new child, old parent, cx, cy, cz) and
    ``parents`` rows (new parent, old child, cx, cy, cz).
    """
    leaves = _Leaves(mesh)
    ndim = mesh.ndim
    offsets = _offsets(ndim)
    kids = _children(ndim)
    refine, coarsen = np.asarray(refine, dtype=bool).tolist(), np.asarray(coarsen, dtype=bool).tolist()
    to_refine = {k for k, b in leaves.leaf.items() if refine[b]}
    queue = list(to_refine)
    while queue:
        level, *index = queue.pop()
        for o in offsets:
            key = leaves.region(level, [index[d] + o[d] for d in range(3)])
            if key is None:
                continue
            holder = leaves.containing(key)
            if holder is not None and holder[0] < level and holder not in to_refine:
                to_refine.add(holder)
                queue.append(holder)
    groups = {}
    for key, b in leaves.leaf.items():
        if coarsen[b] and key not in to_refine:
            level, *index = key
            groups.setdefault((level - 1, index[0] >> 1, index[1] >> 1, index[2] >> 1), []).append(key)
    merged = {}
    for parent in sorted(groups, key=lambda k: -k[0]):
        members = groups[parent]
        if len(members) != len(kids):
            continue
        plevel, *pindex = parent
        balanced = True
        for o in offsets:
            key = leaves.region(plevel, [pindex[d] + o[d] for d in range(3)])
            if key is None:
                continue
            holder = leaves.containing(key)
            if holder is not None:
                if holder[0] < plevel - 1:
                    balanced = False
                continue
            for c in kids:
                child = (plevel + 1,) + tuple(2 * key[1 + d] + c[d] for d in range(3))
                if child not in leaves.leaf or child in to_refine:
                    balanced = False
                    break
            if not balanced:
                break
        if not balanced:
            continue
        for key in members:
            del leaves.leaf[key]
        leaves.leaf[parent] = -1
        merged[parent] = members
    if not to_refine and not merged:
        return None
    entries = []  # (level, index, kind, payload)
    for key, b in leaves.leaf.items():
        if b < 0:
            continue
        if key in to_refine:
            level, *index = key
            for c in kids:
                entries.append((level + 1, [2 * index[d] + c[d] for d in range(3)], "child", (b,) + c))
        else:
            entries.append((key[0], list(key[1:]), "keep", b))
    for parent, members in merged.items():
        entries.append((parent[0], list(parent[1:]), "parent", members))
    level = np.array([e[0] for e in entries], dtype=np.int64)
    index = np.array([e[1] for e in entries], dtype=np.int64).reshape(-1, 3)
    order = np.argsort(morton_keys(level, index, mesh.max_level), kind="stable")
    keep, children, parents = [], [], []
    for new, e in enumerate(entries[i] for i in order):
        if e[2] == "keep":
            keep.append((new, e[3]))
        elif e[2] == "child":
            children.append((new,) + e[3])
        else:
            for key in e[3]:
                old = leaves_index(mesh, key)
                parents.append((new, old) + tuple(key[1 + d] & 1 for d in range(3)))
    return {"level": level[order], "index": index[order],
            "keep": np.array(keep, dtype=np.int64).reshape(-1, 2),
            "children": np.array(children, dtype=np.int64).reshape(-1, 5),
            "parents": np.array(parents, dtype=np.int64).reshape(-1, 5)}


def leaves_index(mesh: BlockMesh, key: tuple) -> int:
    """Index of the leaf block with key (level, i, j, k) in ``mesh``."""
    return int(mesh.lookup(np.array([key[0]]), np.array([key[1:]]))[0])


def remesh(mesh: BlockMesh, state: HydroState, plan: dict) -> tuple[BlockMesh, HydroState]:
    """The new mesh of ``plan`` and the state moved onto it (the first ghost layer of ``state``
    filled on every axis: a new child's prolongation reads its parent cells' face neighbours)."""
    new_mesh = planned_mesh(mesh, plan)
    return new_mesh, moved_state(mesh, new_mesh, state, plan, 0, new_mesh.nblocks, np.zeros)


def plan_rows(plan: dict, lo: int, hi: int) -> dict:
    """The rows of ``plan`` (:func:`plan_leaves`) that build the new blocks ``lo .. hi - 1``
    (``keep``, ``children`` and ``parents``; the new leaves' ``level`` and ``index`` as they are)."""
    rows = dict(plan)
    for name in ("keep", "children", "parents"):
        new = plan[name][:, 0]
        rows[name] = np.ascontiguousarray(plan[name][(new >= lo) & (new < hi)])
    return rows


def plan_sources(plan: dict, lo: int, hi: int) -> np.ndarray:
    """The old blocks (sorted int64 block numbers) that the new blocks ``lo .. hi - 1`` of
    ``plan`` are made from: a kept block itself, a new child's parent, a new parent's children."""
    rows = plan_rows(plan, lo, hi)
    return np.unique(np.concatenate([rows["keep"][:, 1], rows["children"][:, 1], rows["parents"][:, 1]]))


def planned_costs(plan: dict, costs: np.ndarray, ndim: int) -> np.ndarray:
    """(new NB,) int64 estimated cost of each new block of ``plan`` from the old blocks' ``costs``
    (:func:`~impactpipe.hydro.parallel.decomposition.block_costs`): a kept block's own, a new
    child's its parent's (a child has as many cells as its parent), a new parent's the mean of
    its 2^ndim children's (rounded down)."""
    out = np.zeros(len(plan["level"]), dtype=np.int64)
    out[plan["keep"][:, 0]] = costs[plan["keep"][:, 1]]
    out[plan["children"][:, 0]] = costs[plan["children"][:, 1]]
    parents = plan["parents"]
    np.add.at(out, parents[:, 0], costs[parents[:, 1]])
    out[np.unique(parents[:, 0])] //= 2 ** ndim
    return out


def moved_state(mesh: BlockMesh, new_mesh: BlockMesh, state: HydroState, plan: dict, lo: int, hi: int,
                zeros) -> HydroState:
    """The state on the new blocks of ``plan`` (on ``new_mesh``, :func:`planned_mesh`), of which
    the blocks ``lo .. hi - 1`` are moved from ``state`` (whose first ghost layer is filled on
    every axis in the old blocks they read, :func:`remesh`) and the others left zero; each array
    from ``zeros(shape)``.  Kept blocks are copied ghosts included, new children prolonged from
    their parent, new parents restricted from their children."""
    nq = state.arhoq.shape[1] // state.nmat
    shapes = HydroState.shapes(new_mesh, state.nmat, nq)
    new = HydroState(**{name: zeros(shapes[name]) for name in FIELDS})
    if (lo, hi) != (0, new_mesh.nblocks):
        plan = plan_rows(plan, lo, hi)
    runs = _kept_runs(plan["keep"])
    for name in FIELDS:
        old_field, new_field = getattr(state, name), getattr(new, name)
        for new_start, old_start, length in runs:
            new_field[new_start:new_start + length] = old_field[old_start:old_start + length]
    src = tuple(getattr(state, name) for name in ("alpha", "arho", "arhoe", "momentum", "energy", "arhoq"))
    dst = tuple(getattr(new, name) for name in ("alpha", "arho", "arhoe", "momentum", "energy", "arhoq"))
    if len(plan["children"]):
        prolong_blocks(src, dst, plan["children"], mesh.block_lo, mesh.block_dx, new_mesh.block_lo,
                       new_mesh.block_dx, mesh.geometry_code, mesh.ndim)
    parents = plan["parents"]
    if len(parents):
        half = mesh.block_cells // 2
        rows = np.arange(half)
        parent_row = new_mesh.block_index[parents[:, 0], 0, None] * mesh.block_cells + parents[:, 2, None] * half + rows
        fine_level = np.repeat(new_mesh.block_level[parents[:, 0]] + 1, half)
        weight0 = axis0_weights(new_mesh, fine_level, 2 * parent_row.reshape(-1)).reshape(len(parents), half, 2)
        restrict_blocks(src, dst, parents, np.ascontiguousarray(weight0))
    return new


def _kept_runs(keep: np.ndarray) -> list[tuple[int, int, int]]:
    """(new start, old start, length) of the runs of consecutive ``keep`` rows (new, old) along
    which both indices step by one: the kept blocks copied a run at a time, by slices (the
    kept blocks keep their Morton order, so the runs are long), instead of gathered and
    scattered by index arrays."""
    if not len(keep):
        return []
    breaks = np.flatnonzero((np.diff(keep[:, 0]) != 1) | (np.diff(keep[:, 1]) != 1)) + 1
    starts = np.concatenate([[0], breaks])
    ends = np.concatenate([breaks, [len(keep)]])
    return [(int(keep[a, 0]), int(keep[a, 1]), int(b - a)) for a, b in zip(starts, ends)]


def planned_mesh(mesh: BlockMesh, plan: dict) -> BlockMesh:
    """The mesh (no state) of the leaves of ``plan`` (:func:`plan_leaves`) over the root grid of ``mesh``."""
    return BlockMesh.from_leaves(mesh.geometry, mesh.domain_lo, mesh.domain_hi, mesh.blocks_per_axis,
                                 mesh.block_cells, mesh.boundaries, plan["level"], plan["index"], mesh.max_level)


def refined(mesh: BlockMesh, refine: np.ndarray) -> BlockMesh | None:
    """``mesh`` with the blocks flagged in ``refine`` (NB,) split (2:1 balanced, nothing coarsened).

    Flags at ``max_level`` are dropped; None when no block splits.
    """
    refine = np.asarray(refine, dtype=bool) & (mesh.block_level < mesh.max_level)
    plan = plan_leaves(mesh, refine, np.zeros(mesh.nblocks, dtype=bool))
    return None if plan is None else planned_mesh(mesh, plan)


def refine_to(mesh: BlockMesh, wanted_level) -> BlockMesh:
    """A mesh (no state) whose blocks are refined until each reaches ``wanted_level(mesh)``.

    ``wanted_level`` maps a mesh to the (NB,) level each of its blocks should have at least
    (capped by ``max_level``); 2:1 balance may refine further.  Used to build the initial
    mesh of a problem before its state is set.
    """
    for _ in range(mesh.max_level):
        finer = refined(mesh, np.asarray(wanted_level(mesh)) > mesh.block_level)
        if finer is None:
            break
        mesh = finer
    return mesh


def refine_initial(mesh: BlockMesh, build, wanted_level=None):
    """The simulation ``build(mesh)`` on ``mesh`` refined where its refinement rule flags its initial state.

    ``build`` maps a mesh to a new Simulation (:class:`impactpipe.hydro.solver.Simulation`) whose
    initial state the problem sets on that mesh; ``wanted_level`` (optional, as in
    :func:`refine_to`) asks for levels the rule cannot see on a coarse mesh, such as a source
    smaller than a root cell.  After :func:`refine_to`, the blocks that the simulation's
    rule flags to refine (:meth:`~impactpipe.hydro.solver.Simulation.refinement_flags`) split
    and the problem sets its state again on the finer mesh, until no block is flagged: every
    cell holds the initial data at its own size (none is prolonged), and the finest level
    is reached only where the rule asks for it (no finest-level copy of the whole domain is
    made).  Coarsening is left to the run's regrids.  A uniform mesh is built once.
    """
    if wanted_level is not None:
        mesh = refine_to(mesh, wanted_level)
    sim = build(mesh)
    while sim.mesh.adaptive:
        finer = refined(sim.mesh, sim.refinement_flags()[0])
        if finer is None:
            break
        sim = build(finer)
    return sim


def summed_rows(counters: np.ndarray, nblocks: int) -> np.ndarray:
    """Per-block counters for a new mesh of ``nblocks`` blocks: the old totals in row 0."""
    out = np.zeros((nblocks,) + counters.shape[1:], dtype=counters.dtype)
    out[0] = counters.sum(axis=0)
    return out


def rule_from_config(refinement: dict | None) -> RefinementRule:
    """A :class:`RefinementRule` from the ``hydro.refinement`` mapping (missing keys: defaults)."""
    if not refinement:
        return RefinementRule()
    values = dict(refinement)
    values["boxes"] = tuple((tuple(b["lo"]), tuple(b["hi"]), int(b["level"])) for b in values.get("boxes", ()))
    return RefinementRule(**values)
