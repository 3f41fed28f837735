"""The candidate search both broad phases run: the point-triangle and edge-edge pairs two
grids report near each other, listed as a ``ContactList``'s rows in the order of a serial
search.

A search has one query per triangle (the particles near it), then one per edge (the edges
near it that pair with it, each pair once: the grid's ``for_each_partner``). Its owner
bins the particles and the edges in two grids (``hashgrid.py``: points for the proximity
list, ``broad.py``; swept boxes for a step's swept search, ``swept.py``) and gives each
query its box (``Search.lo``, ``hi``); ``Search.run`` visits, for each query, the grid's
items in its box, leaves out pairs that share a particle (or a seam's pair of them:
``topology.SelfCollisionTable.same``), pairs of pinned particles only
and pairs the owner's ``keep`` turns down, and marks the pairs that touch by
construction (``topology.py``) as ones that do not repel (``ContactList.repels``; they
are still listed for the guard).

Blocks of QUERY_BLOCK consecutive queries run in parallel, each block on one thread
appending what its queries find to its own ``block_slots`` slots; a prefix sum over the
queries' counts lays out the rows, so on CPUs the list's order (and every sum over it) is
that of a serial search whatever the threads. A search that found more than its slots,
its grids or its list hold runs again larger (``CandidateSearch.fit``).
"""
import taichi as ti

from ..runtime import serial_count
from .hashgrid import blocks_for, exclusive_scan

POINT_TRIANGLE, EDGE_EDGE = 0, 1
# one query of the search costs about as much as this many items of the loops that
# runtime.SERIAL_BELOW is set for, so its loop goes parallel from that many / this
SEARCH_COST = 16
QUERY_BLOCK = 64
# a block's slots for what its queries find, and the list's rows, at first, per query
# (triangle or edge): a search that overflows them is made again larger, and every kernel
# that reads it compiles again (seconds, in the middle of a run: the 64 x 64 fold's
# proximity list needed 19 a query where the layers overlap, projective's near search at a
# margin of one thickness 43; cloth_pile's swept search outgrew half of these). Chosen so
# that no shipped scene grows them (docs/contact.md, "Compile once")
SLOTS_PER_QUERY = 64
ROWS_PER_QUERY = 16


@ti.func
def every_pair(ids, kind):
    """The ``keep`` that takes every pair the grids report."""
    return True


@ti.data_oriented
class Search:
    """The fields of one search: each query's box (``lo``, ``hi``, in the grids' float
    type), the grids it visits (``points``, ``edges``: ``hashgrid.PointGrid`` or
    ``BoxGrid``) and what the queries found, ``block_slots`` entries a block of queries.
    ``keep(ids, kind)``: a ``ti.func`` that says whether a pair the grids report is a
    candidate. A kernel compiled for one search keeps reading its fields: a larger search
    is a new one."""

    def __init__(self, table, inv_mass, grids, block_slots, keep):
        self.table, self.inv_mass = table, inv_mass
        self.points, self.edges = grids
        self.keep = keep
        self.queries = table.triangle_count + table.edge_count
        self.blocks = blocks_for(self.queries, QUERY_BLOCK)
        self.block_slots = block_slots
        self.lo = ti.Vector.field(3, self.points.real, shape=self.queries)
        self.hi = ti.Vector.field(3, self.points.real, shape=self.queries)
        self.found = ti.field(ti.i32, shape=self.blocks * block_slots)
        self.fill = ti.field(ti.i32, shape=self.blocks)
        self.found_count = ti.field(ti.i32, shape=self.queries)
        self.found_start = ti.field(ti.i32, shape=self.queries + 1)
        self.scan_blocks = ti.field(ti.i32, shape=blocks_for(self.queries))

    @ti.func
    def run(self, cl: ti.template()):
        """Run every query on the grids and write what they found as the rows of ``cl``
        (those within its capacity). Returns (the rows found, the most a block of queries
        found): more than cl's capacity or ``block_slots`` means search again larger. Call
        at a kernel's top level, after the grids' ``build`` and the boxes."""
        Q, B, slots = ti.static(self.queries, self.blocks, self.block_slots)
        T = ti.static(self.table.triangle_count)
        ti.loop_config(serialize=ti.static(serial_count(SEARCH_COST * Q)))
        for blk in range(B):
            self.fill[blk] = 0
            for q in range(blk * QUERY_BLOCK, ti.min((blk + 1) * QUERY_BLOCK, Q)):
                self.found_count[q] = 0
                if q < T:
                    self.points.for_each(self.lo[q], self.hi[q], -1, self._point_triangle, q)
                else:
                    self.edges.for_each_partner(self.lo[q], self.hi[q], q - T, self._edge_edge,
                                                 q - T)
        exclusive_scan(self.found_count, self.found_start, self.scan_blocks, Q,
                       ti.static(serial_count(Q)), False)
        most = 0
        ti.loop_config(serialize=ti.static(serial_count(Q)))
        for blk in range(B):
            ti.atomic_max(most, self.fill[blk])
            slot = blk * slots
            for q in range(blk * QUERY_BLOCK, ti.min((blk + 1) * QUERY_BLOCK, Q)):
                row = self.found_start[q]
                for _ in range(self.found_count[q]):
                    if slot < (blk + 1) * slots and row < cl.capacity:
                        self._lay_out(cl, q, slot, row)
                    slot += 1
                    row += 1
        return ti.Vector([self.found_start[Q], most])

    @ti.func
    def _point_triangle(self, item, t):
        tri, p = self.table.triangles[t], self.table.points[item]
        tab = self.table
        if not (tab.same(p, tri[0]) or tab.same(p, tri[1]) or tab.same(p, tri[2])):
            self._consider(ti.Vector([p, tri[0], tri[1], tri[2]]), POINT_TRIANGLE, 1, t, item)

    @ti.func
    def _edge_edge(self, item, e):
        a, b = self.table.edges[e], self.table.edges[item]
        tab = self.table
        if not (tab.same(a[0], b[0]) or tab.same(a[0], b[1]) or tab.same(a[1], b[0])
                or tab.same(a[1], b[1])):
            self._consider(ti.Vector([a[0], a[1], b[0], b[1]]), EDGE_EDGE, 2,
                           self.table.triangle_count + e, item)

    @ti.func
    def _consider(self, ids, kind, n_a, query, item):
        """Record ``item`` for the query if ``keep`` takes the contact ids (n_a particles
        on its first side)."""
        if self.keep(ids, kind):
            self._record(ids, n_a, query, item)

    @ti.func
    def _record(self, ids, n_a, query, item):
        """Append ``item`` to the query's block with whether the pair touches by
        construction (``topology.excluded``) in its lowest bit, unless all four particles
        are pinned."""
        free = False
        for k in ti.static(range(4)):
            if self.inv_mass[ids[k]] > 0.0:
                free = True
        if free:
            blk = query // QUERY_BLOCK
            k = self.fill[blk]
            if k < self.block_slots:
                self.found[blk * self.block_slots + k] = 2 * item + ti.cast(
                    self.table.excluded(ids, n_a), ti.i32)
            self.fill[blk] = k + 1
            self.found_count[query] += 1

    @ti.func
    def _lay_out(self, cl, q, slot, row):
        """Write found entry ``slot`` of query q as list row ``row``."""
        T = ti.static(cl.table.triangle_count)
        entry = self.found[slot]
        item = entry // 2
        if q < T:
            tri = cl.table.triangles[q]
            cl.ids[row] = ti.Vector([cl.table.points[item], tri[0], tri[1], tri[2]])
            cl.kind[row] = POINT_TRIANGLE
        else:
            a, b = cl.table.edges[q - T], cl.table.edges[item]
            cl.ids[row] = ti.Vector([a[0], a[1], b[0], b[1]])
            cl.kind[row] = EDGE_EDGE
        cl.repels[row] = ti.cast(1 - entry % 2, ti.u8)


class CandidateSearch:
    """A ``Search`` (``search``) on two grids (``grids``) and the ``ContactList`` it fills
    (``candidates``, ``count`` rows in use), made again larger when a search found more
    than they hold. Subclasses make the list (``_list(capacity)``) and, where their grids
    have a capacity a search can exceed, the grids (``_regrid(entries)``)."""

    def __init__(self, table, inv_mass, grids, keep=every_pair):
        self.table, self.inv_mass, self.grids, self.keep = table, inv_mass, grids, keep
        self.search = self._search(SLOTS_PER_QUERY * QUERY_BLOCK)
        self.candidates = self._list(ROWS_PER_QUERY * (table.point_count + table.edge_count))
        self.count = 0

    def _search(self, block_slots):
        return Search(self.table, self.inv_mass, self.grids, block_slots, self.keep)

    def fit(self, run):
        """Run ``run()`` until the search, its grids and the list held what it found; what
        overflowed is made twice what it needed. run: a search into ``search`` and
        ``candidates`` that returns the rows found, the most a block of queries found,
        then the entries each grid needed where the grids have a capacity. Sets and
        returns ``count``."""
        while True:
            rows, most, *entries = (int(v) for v in run())
            regrid = any(n > grid.capacity for n, grid in zip(entries, self.grids))
            reslot = regrid or most > self.search.block_slots
            longer = rows > self.candidates.capacity
            if not (reslot or longer):
                self.count = rows
                return rows
            if regrid:
                self._regrid(2 * max(entries))
            if reslot:
                self.search = self._search(max(2 * most, self.search.block_slots))
            if longer:
                self.candidates = self._list(2 * rows)
