"""The guard's broad phase for one step: the pairs whose swept boxes meet.

Over a step each particle moves on the straight path from x0 to x1, and a triangle or an
edge stays inside the box of its vertices' start and end positions (the box is convex and
holds every vertex all along). Two primitives can come within the thickness T during the
step only if those boxes, grown by T, overlap. ``SweptSearch`` lists every such
point-triangle and edge-edge pair sharing no particle for the guard (those that touch by
construction too: they do not repel, but must not cross either)
when the proximity list does not cover the step (``broad.BroadPhase.covers``): at one step
per frame cloth can move several of its spacings relative to other cloth, and a skin that
large would list most pairs of two cloths facing each other, where swept boxes list the
few each particle's path can meet.

The boxes are binned in uniform cells hashed into a table: each point's and edge's box
into every cell it overlaps (a count, a prefix sum, a scatter, as ``hashgrid.py`` does
for points), and each triangle's and edge's box visits the cells it overlaps. A pair
found in several cells is kept only in the first cell of their overlap (the corner of
the two cell ranges' intersection), so each pair is listed once. The cell is the larger of
the longest edge, T and a third of the longest path, so a box spans at most a few cells a
side.

The guard then moves end positions off their paths (its projection, the colliders'
sweep), mostly back toward where they started. The boxes are grown by a margin besides,
so one search serves every motion whose ends stay within the margin of the searched
paths' boxes (``SweptSearch.holds``), and a step searches again only where the guard moved
a particle farther.
"""
import taichi as ti

from ..runtime import serial_count
from .broad import QUERY_BLOCK, SEARCH_COST, ContactList, lay_out, record
from .hashgrid import blocks_for, exclusive_scan


@ti.data_oriented
class BoxGrid:
    """Boxes of ``n`` items binned into every hashed cell they overlap."""

    def __init__(self, n, capacity):
        size = 1024
        while size < 2 * n:
            size *= 2
        self.n, self.size, self.capacity = max(n, 1), size, capacity
        self.lo = ti.Vector.field(3, ti.f32, shape=self.n)
        self.hi = ti.Vector.field(3, ti.f32, shape=self.n)
        self.cells = ti.field(ti.i32, shape=self.n)          # cells each box overlaps
        self.first = ti.field(ti.i32, shape=self.n + 1)       # its first entry
        self.item_blocks = ti.field(ti.i32, shape=blocks_for(self.n))
        self.entry_item = ti.field(ti.i32, shape=capacity)
        self.entry_cell = ti.Vector.field(3, ti.i32, shape=capacity)
        self.order = ti.field(ti.i32, shape=capacity)         # entries in bucket order
        self.count = ti.field(ti.i32, shape=size)
        self.start = ti.field(ti.i32, shape=size + 1)
        self.blocks = ti.field(ti.i32, shape=blocks_for(size))
        self.inv_cell = ti.field(ti.f32, shape=())

    @ti.func
    def cell_of(self, x):
        return ti.cast(ti.floor(x * self.inv_cell[None]), ti.i32)

    @ti.func
    def bucket(self, c):
        h = (c[0] * 73856093) ^ (c[1] * 19349663) ^ (c[2] * 83492791)
        return h & (self.size - 1)

    @ti.func
    def build(self, count: ti.template()):
        """Bin the first ``count`` boxes of lo/hi (count: a Python int). Returns the
        entries needed: above ``capacity`` nothing was binned past it (build larger)."""
        serial = ti.static(serial_count(max(count, self.size)))
        ti.loop_config(serialize=serial)
        for i in range(count):
            a, b = self.cell_of(self.lo[i]), self.cell_of(self.hi[i])
            self.cells[i] = (b[0] - a[0] + 1) * (b[1] - a[1] + 1) * (b[2] - a[2] + 1)
        exclusive_scan(self.cells, self.first, self.item_blocks, count, serial, False)
        ti.loop_config(serialize=serial)
        for b in range(self.size):
            self.count[b] = 0
        ti.loop_config(serialize=serial)
        for i in range(count):
            a, b = self.cell_of(self.lo[i]), self.cell_of(self.hi[i])
            e = self.first[i]
            for ci in range(a[0], b[0] + 1):
                for cj in range(a[1], b[1] + 1):
                    for ck in range(a[2], b[2] + 1):
                        if e < self.capacity:
                            c = ti.Vector([ci, cj, ck])
                            self.entry_item[e] = i
                            self.entry_cell[e] = c
                            ti.atomic_add(self.count[self.bucket(c)], 1)
                        e += 1
        total = self.first[count]
        exclusive_scan(self.count, self.start, self.blocks, self.size, serial, True)
        # on CPUs one thread, so that each bucket lists its entries in increasing order
        ti.loop_config(serialize=ti.static(True))
        for e in range(ti.min(total, self.capacity)):
            b = self.bucket(self.entry_cell[e])
            self.order[self.start[b] + ti.atomic_add(self.count[b], 1)] = e
        return total

    @ti.func
    def for_each_overlap(self, lo, hi, after, body: ti.template(), ctx):
        """body(item, ctx) once for every item above ``after`` (-1: all) whose box
        overlaps [lo, hi]: in the first cell of the overlap of the two cell ranges."""
        a, b = self.cell_of(lo), self.cell_of(hi)
        for ci in range(a[0], b[0] + 1):
            for cj in range(a[1], b[1] + 1):
                for ck in range(a[2], b[2] + 1):
                    c = ti.Vector([ci, cj, ck])
                    bk = self.bucket(c)
                    for s in range(self.start[bk], self.start[bk + 1]):
                        e = self.order[s]
                        item = self.entry_item[e]
                        if item > after and (self.entry_cell[e] == c).all() \
                                and (self.lo[item] <= hi).all() and (lo <= self.hi[item]).all():
                            first = ti.max(a, self.cell_of(self.lo[item]))
                            if (first == c).all():
                                body(item, ctx)


@ti.data_oriented
class SweptStore:
    """The fields of one swept search (a kernel compiled for one store keeps reading the
    fields it was compiled with: a larger search is a new store)."""

    def __init__(self, table, inv_mass, capacity, block_slots, entries):
        self.table, self.inv_mass = table, inv_mass
        self.queries = table.triangle_count + table.edge_count
        self.blocks = blocks_for(self.queries, QUERY_BLOCK)
        self.block_slots = block_slots
        self.found_count = ti.field(ti.i32, shape=self.queries)
        self.found_start = ti.field(ti.i32, shape=self.queries + 1)
        self.scan_blocks = ti.field(ti.i32, shape=blocks_for(self.queries))
        self.found = ti.field(ti.i32, shape=self.blocks * block_slots)
        self.fill = ti.field(ti.i32, shape=self.blocks)
        self.points = BoxGrid(table.point_count, entries)
        self.edges = BoxGrid(table.edge_count, entries)
        self.candidates = ContactList(table, inv_mass, capacity, lagged=False)

    @ti.func
    def _point_triangle(self, item, t):
        tri, p = self.table.triangles[t], self.table.points[item]
        if p != tri[0] and p != tri[1] and p != tri[2]:
            record(self, ti.Vector([p, tri[0], tri[1], tri[2]]), 1, t, item)

    @ti.func
    def _edge_edge(self, item, e):
        a, b = self.table.edges[e], self.table.edges[item]
        if a[0] != b[0] and a[0] != b[1] and a[1] != b[0] and a[1] != b[1]:
            record(self, ti.Vector([a[0], a[1], b[0], b[1]]), 2,
                   self.table.triangle_count + e, item)


class SweptSearch:
    """The swept-box candidates of one step (module docstring): ``candidates`` (a
    ``ContactList``) and ``count``; ``anchor`` the end positions and ``margin`` the
    margin it was searched with."""

    def __init__(self, table, inv_mass):
        self.table, self.inv_mass = table, inv_mass
        self.anchor = ti.Vector.field(3, inv_mass.dtype, shape=inv_mass.shape[0])
        self.margin = 0.0
        self.store = SweptStore(table, inv_mass, 8 * (table.point_count + table.edge_count),
                                4 * QUERY_BLOCK, 16 * (table.point_count + table.edge_count))
        self.count = 0

    @property
    def candidates(self):
        return self.store.candidates

    def holds(self, x0, x1):
        """Whether the candidates still hold every pair that can come within the thickness
        on the motion x0 -> x1 (x0: the searched start): each point's x1 within the
        margin of the box of its searched path."""
        return float(excess(self.table.points, x0, self.anchor, x1)) <= self.margin

    def grow(self, capacity, block_slots, entries):
        old = self.store
        self.store = SweptStore(self.table, self.inv_mass, max(old.candidates.capacity, capacity),
                                max(old.block_slots, block_slots),
                                max(old.points.capacity, entries))


@ti.func
def _box(x0, x1, ids: ti.template(), grow):
    """The box of the start and end positions of particles ids, grown by ``grow``."""
    lo = ti.cast(ti.min(x0[ids[0]], x1[ids[0]]), ti.f32)
    hi = ti.cast(ti.max(x0[ids[0]], x1[ids[0]]), ti.f32)
    for k in ti.static(range(1, ids.n)):
        lo = ti.min(lo, ti.cast(ti.min(x0[ids[k]], x1[ids[k]]), ti.f32))
        hi = ti.max(hi, ti.cast(ti.max(x0[ids[k]], x1[ids[k]]), ti.f32))
    return lo - grow, hi + grow


@ti.kernel
def sweep_search(search: ti.template(), x0: ti.template(), x1: ti.template(),
                 thickness: float, margin: float, cell: float) -> ti.types.vector(4, ti.i32):
    """List the swept-box candidates of the step x0 -> x1, boxes grown by ``margin``
    besides, into the store ``search``. Returns (candidates, the most a block of queries
    found, point-grid entries, edge-grid entries): any above its capacity means a larger
    store and another search."""
    P, E, T = ti.static(search.table.point_count, search.table.edge_count,
                        search.table.triangle_count)
    Q, B, slots = ti.static(search.queries, search.blocks, search.block_slots)
    # the boxes are grown by half the thickness each (and the margin): two meet where the
    # primitives can come within the thickness
    half = ti.cast(0.5 * thickness + margin, ti.f32)
    search.points.inv_cell[None] = ti.cast(1.0 / cell, ti.f32)
    search.edges.inv_cell[None] = ti.cast(1.0 / cell, ti.f32)
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for i in range(P):
        p = search.table.points[i]
        lo, hi = _box(x0, x1, ti.Vector([p]), half)
        search.points.lo[i], search.points.hi[i] = lo, hi
    ti.loop_config(serialize=ti.static(serial_count(E)))
    for e in range(E):
        lo, hi = _box(x0, x1, search.table.edges[e], half)
        search.edges.lo[e], search.edges.hi[e] = lo, hi
    point_entries = search.points.build(P)
    edge_entries = search.edges.build(E)
    ti.loop_config(serialize=ti.static(serial_count(SEARCH_COST * Q)))
    for blk in range(B):
        search.fill[blk] = 0
        for q in range(blk * QUERY_BLOCK, ti.min((blk + 1) * QUERY_BLOCK, Q)):
            search.found_count[q] = 0
            if q < T:
                lo, hi = _box(x0, x1, search.table.triangles[q], half)
                search.points.for_each_overlap(lo, hi, -1, search._point_triangle, q)
            else:
                e = q - T
                search.edges.for_each_overlap(search.edges.lo[e], search.edges.hi[e], e,
                                              search._edge_edge, e)
    exclusive_scan(search.found_count, search.found_start, search.scan_blocks, Q,
                   ti.static(serial_count(Q)), False)
    most = 0
    ti.loop_config(serialize=ti.static(serial_count(Q)))
    for blk in range(B):
        ti.atomic_max(most, search.fill[blk])
        slot = blk * slots
        for q in range(blk * QUERY_BLOCK, ti.min((blk + 1) * QUERY_BLOCK, Q)):
            row = search.found_start[q]
            for _ in range(search.found_count[q]):
                if slot < (blk + 1) * slots and row < search.candidates.capacity:
                    lay_out(search, search.candidates, q, slot, row)
                slot += 1
                row += 1
    return ti.Vector([search.found_start[Q], most, point_entries, edge_entries])


@ti.kernel
def longest_path(points: ti.template(), x0: ti.template(), x1: ti.template()) -> ti.f64:
    """The longest distance a particle of ``points`` moves from x0 to x1 (m)."""
    longest = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial_count(points.shape[0])))
    for i in range(points.shape[0]):
        p = points[i]
        ti.atomic_max(longest, ti.cast((x1[p] - x0[p]).norm(), ti.f64))
    return longest


@ti.kernel
def longest_edge(table: ti.template(), x: ti.template()) -> ti.f64:
    longest = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial_count(table.edge_count)))
    for e in range(table.edge_count):
        ti.atomic_max(longest, ti.cast((x[table.edges[e][0]] - x[table.edges[e][1]]).norm(),
                                       ti.f64))
    return longest


@ti.kernel
def excess(points: ti.template(), x0: ti.template(), anchor: ti.template(),
           x: ti.template()) -> ti.f64:
    """How far x lies outside the box of x0 and anchor, in the largest coordinate, over
    ``points`` (m)."""
    most = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial_count(points.shape[0])))
    for i in range(points.shape[0]):
        p = points[i]
        lo, hi = ti.min(x0[p], anchor[p]), ti.max(x0[p], anchor[p])
        out = ti.max(lo - x[p], x[p] - hi, 0.0).max()
        ti.atomic_max(most, ti.cast(out, ti.f64))
    return most


def search_step(search, x0, x1, thickness, margin):
    """Fill ``search.candidates`` with the step's swept-box candidates, boxes grown by
    ``margin`` (m) besides; returns their number (also ``search.count``)."""
    table = search.table
    path = float(longest_path(table.points, x0, x1))
    cell = max(float(longest_edge(table, x0)), thickness + 2.0 * margin, path / 3.0, 1e-9)
    search.anchor.copy_from(x1)
    search.margin = margin
    while True:
        store = search.store
        count, most, point_entries, edge_entries = (int(v) for v in sweep_search(
            store, x0, x1, thickness, margin, cell))
        entries = max(point_entries, edge_entries)
        if entries > store.points.capacity or most > store.block_slots \
                or count > store.candidates.capacity:
            search.grow(2 * count, 2 * most, 2 * entries)
        else:
            break
    search.count = count
    return count
