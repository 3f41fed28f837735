"""Mesh colliders as signed distance fields: a rigid closed mesh baked once into a narrow
band of a grid in its own frame, then sampled per particle as an analytic shape is.

``SdfStore(store, colliders)`` takes every mesh collider of a scene (``MeshStore``'s
order), decides which can be a field (``plan``: closed, rigid, no part thinner than THIN
cells, a grid of at most MAX_NODES nodes; ``sdf`` False, or a reason against, keeps the
mesh on the certified pairs of ``contact/obstacle.py``), bakes those, and records each
choice with its reason in ``paths``.

The grid: nodes ``cell`` apart (the collider's thickness) in the mesh's own frame, its
cells in blocks of BLOCK^3. A block is kept where its centre lies within the band plus
its half diagonal of the surface (one closest-point query a block), so that every point
within the band lies in a kept block; each kept block stores its (BLOCK + 1)^3 corner
nodes (a face shared with a neighbour is stored twice, so a query reads one block). A
node holds the exact signed distance to the mesh: its closest point through the mesh's
hierarchy (``MeshStore.signed``), negative inside by the pseudo normal of the feature that
point lies on (exact for a closed mesh). Between nodes the distance is the trilinear
interpolation of its cell's eight nodes and its gradient that interpolation's
derivative, so the contact's normal is the interpolated field's.

The band is the thickness plus BAND cells: the farthest a solver asks at rest and while
falling at a few m/s at dt = 1/60 (a step's reach, ``Colliders.begin_solve``). Beyond it
``sample`` answers the band itself, a lower bound of the distance (as the exact query
answers its reach), and says so; the collider table then asks the exact mesh wherever a
caller needs more (a cloth thrown at the mesh), and counts it (``fallbacks``).

Error: the trilinear interpolant of a distance field whose level sets have curvature
radius R at the thickness is within cell^2 / (8 R) of it (a sphere of radius 0.25 m at a
5 mm cell: 12.5 micrometres); a plate thinner than two cells would lose its inside
between the nodes, hence THIN.
"""
import time

import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from .meshstore import TINY, pose

BLOCK = 8            # cells along a block's side
NODES = (BLOCK + 1) ** 3
BAND = 8             # cells of the band beyond the thickness
THIN = 2             # a closed mesh thinner than this many cells somewhere keeps the pairs
SLACK = 1e-3         # a depth within this fraction of THIN cells is THIN cells (rounding)
MAX_NODES = 1 << 24  # nodes a scene's fields may hold (64 MB in float32)
SDF, CERTIFIED = "sdf", "certified"
EMPTY = -1           # a block no point of the band lies in
REACH_CELLS = 1.75   # cells beyond the band that the nodes are exact to (over sqrt(3))


def plan(c, closed, cell):
    """(path, reason) of mesh collider dict c from what the scene says (``closed``: as
    the mesh store takes it): CERTIFIED with why, or SDF with "" where only its depth and
    size remain to be checked. Raises SceneError where ``sdf`` is True and it cannot be
    a field."""
    option = c.get("sdf", "auto")
    why = ""
    if option is False:
        return CERTIFIED, "sdf=False"
    if c["deform"] is not None:
        why = "it deforms: a field baked once cannot follow it"
    elif not closed:
        why = "it is open (two-sided): a sheet is thinner than any cell"
    elif cell <= 0.0:
        why = "its thickness is 0: no cell to tie the grid to"
    return _refuse(option, why)


def _refuse(option, why):
    if why and option is True:
        raise SceneError(f"a mesh collider with sdf=True cannot be a distance field: {why}")
    return (CERTIFIED, why) if why else (SDF, "")


@ti.data_oriented
class SdfStore:
    """The fields of a scene's SDF mesh colliders (module docstring).

    Attributes:
        paths: per mesh of the store, dict: path (SDF or CERTIFIED), reason (why not a
            field, "" for one), cell and band (m), depth (its thinnest part, m, where
            measured), nodes and bake_seconds (a field's).
        of_mesh: (meshes,) i32, each mesh's field index, -1 for a certified one.
        origin (K, 3), cell (K,), band (K,): each field's first node (its mesh's frame),
            node spacing and band (m); dims (K, 3) i32: its blocks along each axis;
            first (K,) i32: its first block in ``table``.
        table: every field's blocks, each one's slot in ``pool`` or EMPTY; pool: (slots,
            NODES) signed distances (m), a block's nodes in x-major order.
        fallbacks: () i32, queries beyond the band the exact mesh answered within the
            caller's reach (``ColliderTable.contact``).
    """

    def __init__(self, store, colliders):
        self.paths = [self._plan(store, m, c) for m, c in enumerate(colliders)]
        fields = [m for m, p in enumerate(self.paths) if p["path"] == SDF]
        real, count = runtime.real(), max(len(fields), 1)
        self.of_mesh = ti.field(ti.i32, shape=max(len(colliders), 1))
        self.origin = ti.Vector.field(3, real, shape=count)
        self.cell = ti.field(real, shape=count)
        self.band = ti.field(real, shape=count)
        self.dims = ti.Vector.field(3, ti.i32, shape=count)
        self.first = ti.field(ti.i32, shape=count)
        self.fallbacks = ti.field(ti.i32, shape=())
        kept = [self._blocks(store, k, m) for k, m in enumerate(fields)]
        nodes = sum(int(near.sum()) for near in kept) * NODES
        if nodes > MAX_NODES:
            for m in fields:
                self.paths[m].update(path=CERTIFIED, reason=(
                    f"the scene's fields would hold {nodes:,} nodes, over {MAX_NODES:,}"))
                _refuse(colliders[m].get("sdf", "auto"), self.paths[m]["reason"])
            fields, kept = [], []
        of_mesh = np.full(self.of_mesh.shape[0], -1, np.int32)
        of_mesh[fields] = np.arange(len(fields))
        self.of_mesh.from_numpy(of_mesh)
        self.count = len(fields)
        slots = [int(near.sum()) for near in kept]
        self.table = ti.field(ti.i32, shape=max(sum(near.size for near in kept), 1))
        self.pool = ti.field(real, shape=(max(sum(slots), 1), NODES))
        self.slot_block = ti.Vector.field(3, ti.i32, shape=max(sum(slots), 1))
        if fields:
            self._bake(store, fields, kept)

    def _plan(self, store, m, c):
        """Mesh m's entry of ``paths``: ``plan``, then its depth against THIN cells."""
        cell = float(c["thickness"])
        path, why = plan(c, store.records[m]["closed"], cell)
        entry = {"path": path, "reason": why, "cell": cell, "band": cell * (1 + BAND),
                 "depth": None, "nodes": 0, "bake_seconds": 0.0}
        if path == SDF:
            entry["depth"] = store.depth(m, 4 * THIN * cell)
            if entry["depth"] < THIN * cell * (1.0 - SLACK):
                entry["path"], entry["reason"] = _refuse(c.get("sdf", "auto"), (
                    f"its thinnest part, {1e3 * entry['depth']:.1f} mm, is under {THIN} "
                    f"cells of {1e3 * cell:.1f} mm"))
        return entry

    def _blocks(self, store, k, m):
        """Field k's parameters for mesh m and its blocks, (dims) int32: 1 where a block's
        centre lies within the band plus its half diagonal of the mesh, else 0."""
        started = time.perf_counter()
        v, cell, band = store.records[m]["v"], self.paths[m]["cell"], self.paths[m]["band"]
        lo, hi = v.min(axis=0) - band, v.max(axis=0) + band
        dims = np.maximum(np.ceil((hi - lo) / (BLOCK * cell)), 1).astype(np.int32)
        self.origin[k], self.cell[k], self.band[k], self.dims[k] = lo, cell, band, dims
        near = np.zeros(int(dims.prod()), np.int32)
        _near_blocks(self, store, k, m, band + 0.5 * np.sqrt(3.0) * BLOCK * cell, near)
        self.paths[m]["bake_seconds"] += time.perf_counter() - started
        return near

    def _bake(self, store, fields, kept):
        """The table's slots and every kept block's nodes (``_bake_nodes``)."""
        table, blocks, slot = [], [], 0
        for k, near in enumerate(kept):
            ids = np.full(near.size, EMPTY, np.int64)
            where = np.flatnonzero(near)
            ids[where] = slot + np.arange(len(where))
            blocks.append(np.stack(np.unravel_index(where, tuple(self.dims[k])), 1))
            self.first[k] = sum(n.size for n in kept[:k])
            table.append(ids)
            slot += len(where)
        self.table.from_numpy(np.concatenate(table).astype(np.int32))
        self.slot_block.from_numpy(np.concatenate(blocks).astype(np.int32))
        slot = 0
        for k, (m, near) in enumerate(zip(fields, kept)):
            started = time.perf_counter()
            count = int(near.sum())
            _bake_nodes(self, store, k, m, slot, count, self.reach(k))
            slot += count
            self.paths[m]["nodes"] = count * NODES
            self.paths[m]["bake_seconds"] += time.perf_counter() - started

    def reach(self, k):
        """How far field k's nodes hold exact distances (m): the band and a cell's
        diagonal, so that every corner of a cell that a point of the band lies in does."""
        return float(self.band[k]) + REACH_CELLS * float(self.cell[k])

    @ti.func
    def sample(self, k, q):
        """(phi, gradient, in band) of field k at q (its mesh's frame): the trilinear
        interpolation of q's cell's nodes and its derivative; beyond the band (band,
        (0, 1, 0), False)."""
        phi, grad, inside = self.band[k], ti.Vector([0.0, 1.0, 0.0]), False
        g = (q - self.origin[k]) / self.cell[k]
        dims = self.dims[k]
        if (g >= 0.0).all() and (g < ti.cast(dims * BLOCK, float)).all():
            i = ti.cast(ti.floor(g), ti.i32)
            b = i // BLOCK
            slot = self.table[self.first[k] + (b[0] * dims[1] + b[1]) * dims[2] + b[2]]
            if slot >= 0:
                f = g - ti.cast(i, float)
                local = i - b * BLOCK
                base = (local[0] * (BLOCK + 1) + local[1]) * (BLOCK + 1) + local[2]
                v = ti.Matrix.zero(float, 2, 4)         # v[x, 2 y + z]
                for a, yz in ti.static(ti.ndrange(2, 4)):
                    v[a, yz] = self.pool[slot, base + a * (BLOCK + 1) ** 2
                                         + (yz // 2) * (BLOCK + 1) + yz % 2]
                x_lerp = [v[0, yz] + f[0] * (v[1, yz] - v[0, yz]) for yz in ti.static(range(4))]
                x_step = [v[1, yz] - v[0, yz] for yz in ti.static(range(4))]
                lower = x_lerp[0] + f[1] * (x_lerp[2] - x_lerp[0])      # z = 0
                upper = x_lerp[1] + f[1] * (x_lerp[3] - x_lerp[1])      # z = 1
                phi = lower + f[2] * (upper - lower)
                dx = ((1.0 - f[2]) * (x_step[0] + f[1] * (x_step[2] - x_step[0]))
                      + f[2] * (x_step[1] + f[1] * (x_step[3] - x_step[1])))
                dy = ((1.0 - f[2]) * (x_lerp[2] - x_lerp[0])
                      + f[2] * (x_lerp[3] - x_lerp[1]))
                # a corner beyond ``reach`` holds it: q is beyond the band
                if ti.max(v.max(), -v.min()) < self.band[k] + REACH_CELLS * self.cell[k]:
                    grad = ti.Vector([dx, dy, upper - lower]) / self.cell[k]
                    inside = True
                else:
                    phi = self.band[k]
        return phi, grad, inside

    @ti.func
    def contact(self, col, k, x, t):
        """(phi, outward unit normal, the surface's velocity at the closest point, in
        band) of world point x against the rigid mesh row ``col`` (field k) at time t."""
        r, c = pose(col, t)
        q = r.transpose() @ (x - c)
        phi, grad, inside = self.sample(k, q)
        nl = ti.Vector([0.0, 1.0, 0.0])
        if grad.norm() > TINY:
            nl = grad.normalized()
        return phi, r @ nl, col.velocity + col.spin.cross(r @ (q - phi * nl)), inside


@ti.kernel
def _near_blocks(sdf: ti.template(), store: ti.template(), k: ti.i32, m: ti.i32,
                 reach: float, near: ti.types.ndarray()):
    """near[b] = 1 where block b's centre of field k lies within ``reach`` of mesh m."""
    dims = sdf.dims[k]
    for b in range(near.shape[0]):
        index = ti.Vector([b // (dims[1] * dims[2]), (b // dims[2]) % dims[1], b % dims[2]])
        centre = sdf.origin[k] + sdf.cell[k] * BLOCK * (ti.cast(index, float) + 0.5)
        _phi, _n, _u, tri, _w = store.signed(m, centre, 0.0, reach)
        near[b] = 1 if tri >= 0 else 0


@ti.kernel
def _bake_nodes(sdf: ti.template(), store: ti.template(), k: ti.i32, m: ti.i32,
                first: ti.i32, count: ti.i32, reach: float):
    """The nodes of field k's ``count`` blocks from slot ``first``: each one's signed
    distance to mesh m, or ``reach`` where the mesh lies farther (``SdfStore.reach``)."""
    for s, n in ti.ndrange((first, first + count), NODES):
        local = ti.Vector([n // (BLOCK + 1) ** 2, (n // (BLOCK + 1)) % (BLOCK + 1),
                           n % (BLOCK + 1)])
        q = sdf.origin[k] + sdf.cell[k] * ti.cast(sdf.slot_block[s] * BLOCK + local, float)
        phi, _n, _u, _tri, _w = store.signed(m, q, 0.0, reach)
        sdf.pool[s, n] = phi
