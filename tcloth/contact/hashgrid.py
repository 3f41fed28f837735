"""A uniform grid of cubic cells hashed into a table, sorted by counting sort in kernels.

Items (points) are binned by the cell that holds them; the cells are hashed into a table
of ``size`` buckets (a power of two, at least twice the number of items), counted, the
counts turned into bucket starts by a blocked prefix sum (per-block sums in parallel, a
serial scan over the blocks, per-block scans in parallel) and the items scattered into
``order`` (on CPUs in increasing order per bucket). ``for_each_in_box`` visits the
items in a box, each once: it scans the cells the box overlaps, and a bucket shared by
two cells (a hash collision) is filtered by the item's own cell.

The cost of a build is O(items + size); of a query, the cells the box covers times the
items per cell, which the caller bounds by choosing the cell size (``set_cell``).
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
class HashGrid:
    """Cells for ``n`` items. Fill ``pos`` (n,) vec3 with the items' positions, then call
    ``build`` inside a kernel (it has top-level loops)."""

    def __init__(self, n):
        size = 1024
        while size < 2 * n:
            size *= 2
        self.n, self.size = max(n, 1), size
        self.pos = ti.Vector.field(3, runtime.real(), shape=self.n)
        self.cell = ti.Vector.field(3, ti.i32, shape=self.n)
        self.order = ti.field(ti.i32, shape=self.n)
        self.count = ti.field(ti.i32, shape=size)
        self.start = ti.field(ti.i32, shape=size + 1)
        self.blocks = ti.field(ti.i32, shape=blocks_for(size))
        self.inv_cell = ti.field(runtime.real(), shape=())

    @ti.func
    def cell_of(self, x):
        return ti.cast(ti.floor(x * self.inv_cell[None]), ti.i32)

    @ti.func
    def bucket(self, c):
        h = (c[0] * 73856093) ^ (c[1] * 19349663) ^ (c[2] * 83492791)
        return h & (self.size - 1)

    @ti.func
    def set_cell(self, size):
        self.inv_cell[None] = 1.0 / size

    @ti.func
    def build(self, count: ti.template()):
        """Bin the first ``count`` items of ``pos`` (count: a Python int)."""
        serial = ti.static(runtime.serial_count(max(count, self.size)))
        ti.loop_config(serialize=serial)
        for b in range(self.size):
            self.count[b] = 0
        ti.loop_config(serialize=serial)
        for i in range(count):
            c = self.cell_of(self.pos[i])
            self.cell[i] = c
            ti.atomic_add(self.count[self.bucket(c)], 1)
        exclusive_scan(self.count, self.start, self.blocks, self.size, serial, True)
        # on CPUs one thread: each bucket then lists its items in increasing order, so a
        # query visits them in the same order whatever the threads (on GPUs a serial loop
        # would cost more than the whole search; the order within a bucket may vary)
        ti.loop_config(serialize=ti.static(runtime.cpu()))
        for i in range(count):
            b = self.bucket(self.cell[i])
            self.order[self.start[b] + ti.atomic_add(self.count[b], 1)] = i

    @ti.func
    def for_each_in_box(self, lo, hi, after, body: ti.template(), ctx):
        """body(item, ctx) for every item above ``after`` (-1: all) whose position lies in
        the box [lo, hi]."""
        a, b = self.cell_of(lo), self.cell_of(hi)
        # nested ranges: ti.ndrange recovers i, j, k by two integer divisions per cell
        for i in range(a[0], b[0] + 1):
            for j in range(a[1], b[1] + 1):
                for k in range(a[2], b[2] + 1):
                    bk = self.bucket(ti.Vector([i, j, k]))
                    for s in range(self.start[bk], self.start[bk + 1]):
                        item = self.order[s]
                        if item > after:
                            d, p = self.cell[item], self.pos[item]
                            if d[0] == i and d[1] == j and d[2] == k and (lo <= p).all() \
                                    and (p <= hi).all():
                                body(item, ctx)
