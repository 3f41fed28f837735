"""Uniform grids of cubic cells hashed into a table, sorted by counting sort in kernels.

``CellHash`` is the table: cells of a size set in kernels (``set_cell``) hashed into
``size`` buckets (a power of two, at least twice the number of items), entries counted
per bucket, the counts turned into bucket starts by a blocked prefix sum (per-block sums
in parallel, a serial scan over the blocks, per-block scans in parallel) and the entries
scattered into ``order`` (in increasing order per bucket where the scatter runs on one
thread). Two grids bin on it:

  - ``PointGrid``: points, each in the cell that holds it. ``for_each`` visits the points
    in a box, each once: it scans the cells the box overlaps, and a bucket shared by two
    cells (a hash collision) is filtered by the point's own cell.
  - ``BoxGrid``: boxes, each in every cell it overlaps (an entry per cell, up to a
    capacity). ``for_each`` visits the boxes that overlap a box, each once: in the first
    cell of the overlap of the two boxes' cell ranges.

Both answer ``for_each_partner``: the items a query's own item pairs with, each pair of
items once. ``PointGrid`` skips the cells before the item's own (each pair is then found
from its earlier cell), ``BoxGrid`` the boxes of lower index.

The cost of a build is O(entries + size); of a query, the cells the box covers times the
entries per cell, which the caller bounds by choosing the cell size.
"""
import taichi as ti

from .. import runtime

BLOCK = 256


def blocks_for(n, block=BLOCK):
    """How many blocks of ``block`` cover n entries (at least one; with the default,
    what ``exclusive_scan`` needs)."""
    return max((n + block - 1) // block, 1)


@ti.func
def exclusive_scan(count: ti.template(), start: ti.template(), blocks: ti.template(),
                   n: ti.template(), serial: ti.template(), reset: ti.template()):
    """start[k] = count[0] + ... + count[k - 1] for k = 0..n (start has n + 1 entries,
    blocks ``blocks_for(n)``): per-block sums, a serial scan over the blocks, per-block
    scans; the block loops run on one thread where ``serial``. reset: count = 0 after.
    Call at a kernel's top level (it has top-level loops)."""
    ti.loop_config(serialize=serial)
    for blk in range(ti.static(blocks_for(n))):
        total = 0
        for k in range(blk * BLOCK, ti.min((blk + 1) * BLOCK, n)):
            total += count[k]
        blocks[blk] = total
    ti.loop_config(serialize=True)
    for _ in range(1):
        running = 0
        for blk in range(ti.static(blocks_for(n))):
            part = blocks[blk]
            blocks[blk] = running
            running += part
        start[n] = running
    ti.loop_config(serialize=serial)
    for blk in range(ti.static(blocks_for(n))):
        running = blocks[blk]
        for k in range(blk * BLOCK, ti.min((blk + 1) * BLOCK, n)):
            start[k] = running
            running += count[k]
            if ti.static(reset):
                count[k] = 0


@ti.data_oriented
class CellHash:
    """The hashed table of a grid of ``n`` items: cells of 1 / ``inv_cell`` a side (of
    float type ``real``), a bucket per cell, and ``order``, up to ``capacity`` entries
    sorted by bucket (``start``: each bucket's first)."""

    def __init__(self, n, capacity, real):
        size = 1024
        while size < 2 * n:
            size *= 2
        self.n, self.size, self.capacity, self.real = max(n, 1), size, capacity, real
        self.order = ti.field(ti.i32, shape=capacity)
        self.count = ti.field(ti.i32, shape=size)
        self.start = ti.field(ti.i32, shape=size + 1)
        self.blocks = ti.field(ti.i32, shape=blocks_for(size))
        self.inv_cell = ti.field(real, shape=())

    @ti.func
    def cell_of(self, x):
        return ti.cast(ti.floor(x * self.inv_cell[None]), ti.i32)

    @ti.func
    def bucket(self, c):
        h = (c[0] * 73856093) ^ (c[1] * 19349663) ^ (c[2] * 83492791)
        return h & (self.size - 1)

    @ti.func
    def set_cell(self, size):
        self.inv_cell[None] = ti.cast(1.0 / size, self.real)

    @ti.func
    def clear(self, serial: ti.template()):
        """Zero the buckets' counts (a top-level loop)."""
        ti.loop_config(serialize=serial)
        for b in range(self.size):
            self.count[b] = 0

    @ti.func
    def sort(self, cells: ti.template(), entries, serial: ti.template(),
             in_order: ti.template()):
        """``order``: entries 0..entries - 1 by the bucket of their cell ``cells[e]``, each
        of which ``count`` counted (it is 0 after). The scatter runs on one thread where
        ``in_order``: each bucket then lists its entries in increasing order. Call at a
        kernel's top level."""
        exclusive_scan(self.count, self.start, self.blocks, self.size, serial, True)
        ti.loop_config(serialize=in_order)
        for e in range(entries):
            b = self.bucket(cells[e])
            self.order[self.start[b] + ti.atomic_add(self.count[b], 1)] = e


@ti.data_oriented
class PointGrid(CellHash):
    """Cells for ``n`` points. Fill ``pos`` (n,) vec3 with their positions, then call
    ``build`` inside a kernel (it has top-level loops)."""

    def __init__(self, n):
        super().__init__(n, max(n, 1), runtime.real())
        self.pos = ti.Vector.field(3, self.real, shape=self.n)
        self.cell = ti.Vector.field(3, ti.i32, shape=self.n)

    @ti.func
    def build(self, count: ti.template()):
        """Bin the first ``count`` points of ``pos`` (count: a Python int)."""
        serial = ti.static(runtime.serial_count(max(count, self.size)))
        self.clear(serial)
        ti.loop_config(serialize=serial)
        for i in range(count):
            c = self.cell_of(self.pos[i])
            self.cell[i] = c
            ti.atomic_add(self.count[self.bucket(c)], 1)
        # on CPUs one thread: each bucket then lists its points in increasing order, so a
        # query visits them in the same order whatever the threads (on GPUs a serial loop
        # would cost more than the whole search; the order within a bucket may vary)
        self.sort(self.cell, count, serial, ti.static(runtime.cpu()))

    @ti.func
    def for_each(self, lo, hi, after, body: ti.template(), ctx):
        """body(item, ctx) for every point above ``after`` (-1: all) that lies in the box
        [lo, hi]."""
        a, b = self.cell_of(lo), self.cell_of(hi)
        # nested ranges: ti.ndrange recovers i, j, k by two integer divisions per cell
        for i in range(a[0], b[0] + 1):
            for j in range(a[1], b[1] + 1):
                for k in range(a[2], b[2] + 1):
                    self._visit(ti.Vector([i, j, k]), lo, hi, after, body, ctx)

    @ti.func
    def for_each_partner(self, lo, hi, own, body: ti.template(), ctx):
        """body(item, ctx) for the points in the box [lo, hi] that pair with point
        ``own`` (in the box) once: those in a cell after own's (cells ordered by their
        indices, lexicographically) and those of higher index in its own cell. Where the
        relation behind the boxes is symmetric (b is in a's box whenever a is in b's),
        each pair is visited once, by the query of its first point in that order, and the
        cells before own's are not scanned: half the cells of ``for_each(lo, hi, own)``."""
        a, b, o = self.cell_of(lo), self.cell_of(hi), self.cell[own]
        for i in range(ti.max(a[0], o[0]), b[0] + 1):
            j0 = a[1] if i > o[0] else ti.max(a[1], o[1])
            for j in range(j0, b[1] + 1):
                k0 = a[2] if i > o[0] or j > o[1] else ti.max(a[2], o[2])
                for k in range(k0, b[2] + 1):
                    c = ti.Vector([i, j, k])
                    self._visit(c, lo, hi, own if (c == o).all() else -1, body, ctx)

    @ti.func
    def _visit(self, c, lo, hi, after, body: ti.template(), ctx):
        """body(item, ctx) for every point above ``after`` in cell c and the box."""
        bk = self.bucket(c)
        for s in range(self.start[bk], self.start[bk + 1]):
            item = self.order[s]
            if item > after:
                p = self.pos[item]
                if (self.cell[item] == c).all() and (lo <= p).all() and (p <= hi).all():
                    body(item, ctx)


@ti.data_oriented
class BoxGrid(CellHash):
    """Boxes of ``n`` items (``lo``, ``hi``, float32) binned into every cell they overlap,
    up to ``capacity`` entries. Fill lo and hi, then call ``build`` inside a kernel."""

    def __init__(self, n, capacity):
        super().__init__(n, capacity, ti.f32)
        self.lo = ti.Vector.field(3, ti.f32, shape=self.n)
        self.hi = ti.Vector.field(3, ti.f32, shape=self.n)
        self.cells = ti.field(ti.i32, shape=self.n)          # cells each box overlaps
        self.first = ti.field(ti.i32, shape=self.n + 1)       # its first entry
        self.item_blocks = ti.field(ti.i32, shape=blocks_for(self.n))
        self.entry_item = ti.field(ti.i32, shape=capacity)
        self.entry_cell = ti.Vector.field(3, ti.i32, shape=capacity)

    @ti.func
    def build(self, count: ti.template()):
        """Bin the first ``count`` boxes of lo/hi (count: a Python int). Returns the
        entries needed: above ``capacity`` nothing was binned past it (build larger)."""
        serial = ti.static(runtime.serial_count(max(count, self.size)))
        ti.loop_config(serialize=serial)
        for i in range(count):
            a, b = self.cell_of(self.lo[i]), self.cell_of(self.hi[i])
            self.cells[i] = (b[0] - a[0] + 1) * (b[1] - a[1] + 1) * (b[2] - a[2] + 1)
        exclusive_scan(self.cells, self.first, self.item_blocks, count, serial, False)
        self.clear(serial)
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
        # one thread, on GPUs too, so that each bucket lists its entries in increasing order
        self.sort(self.entry_cell, ti.min(total, self.capacity), serial, True)
        return total

    @ti.func
    def for_each(self, lo, hi, after, body: ti.template(), ctx):
        """body(item, ctx) once for every box above ``after`` (-1: all) that overlaps
        [lo, hi]: in the first cell of the overlap of the two cell ranges."""
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

    @ti.func
    def for_each_partner(self, lo, hi, own, body: ti.template(), ctx):
        """body(item, ctx) once for every box of higher index than ``own`` that overlaps
        [lo, hi] (``PointGrid.for_each_partner``'s contract)."""
        self.for_each(lo, hi, own, body, ctx)
