"""The self-contact broad phase: which point-triangle and edge-edge pairs can touch
(their gap: ``candidates.gap``). Pairs that touch by construction are left out
(``topology.py``).

``BroadPhase`` keeps a candidate list: every pair whose gap was within thickness + skin at
the positions x_ref of its last build. It runs the candidate search (``search.py``) on
particles and edge midpoints binned in hashed uniform cells of size max(longest edge,
reach) (``hashgrid.PointGrid``): each triangle visits the particles in its box grown by
the reach, each edge the edges whose midpoints lie in its box grown by the reach and half
the longest edge, and a pair is kept where its gap at x_ref is within the reach. Two edges
within the reach lie each in the other's grown box, so each pair is looked for once, by
the edge whose midpoint's cell comes first (``PointGrid.for_each_partner``): the cells
before its own, about half of each edge query's, are not scanned (the edge queries are
the larger part of a build).

The list covers a set of configurations when no two particles have moved, from x_ref to
any of them, by more than the skin relative to each other: twice the largest distance of
a displacement from the centre c of all the displacements' bounding box is at most the
skin (any c bounds |d_i - d_j| <= |d_i - c| + |d_j - c|). Then no pair left out can be
within the thickness in any of them, nor anywhere on a straight path between two of
them, since a displacement on the path lies between its ends'. A motion the particles
share (a cloth falling) costs no rebuild.

The list keeps each row's gap at x_ref (``ref_gap``). A gap is the distance between two
convex hulls of the row's particles, so it shrinks by no more than the largest relative
displacement of a particle of one side and one of the other: at any y a row's gap is at
least its ref_gap less the largest distance from the displacements' centre of a
particle of each side (``moved(y)`` leaves them in ``far``), and a consumer skips the
rows that bound puts beyond the thickness without their closest points (``near``),
which are what a step of an explicit integrator spends its contact time on.

Cost of a build: O(particles + edges + table) for the sort; per triangle or edge, the
cells its box covers (at most 4 and 5 per axis) times the items per cell, which is the
number of layers of cloth within a cell of each other.
"""
import taichi as ti

from .. import runtime
from ..runtime import serial, serial_count
from .candidates import ContactList, gap
from .hashgrid import PointGrid, blocks_for
from .search import EDGE_EDGE, POINT_TRIANGLE, CandidateSearch

# particles per block of the displacement test's reduction
DISPLACEMENT_BLOCK = 1024
# m: what rounding may take from a row's gap at x_ref against its bound (float32
# coordinates near 1 m round to 6e-8 m; a gap is a few operations on them)
GAP_ROUNDING = 1e-6


@ti.kernel
def _spread(broad: ti.template(), ref: ti.template(), x: ti.template(), y: ti.template(),
            both: ti.template()) -> ti.f64:
    """``spread``."""
    return spread(broad, ref, x, y, both)


@ti.func
def spread(broad, ref, x, y, both: ti.template()):
    """Twice the largest distance of a displacement (x - ref, and y - ref when
    ``both``) from the middle of all the displacements' bounding box: no two particles
    have moved relative to each other by more, from x_ref to x or y or anywhere on the
    straight path between them; each particle's own distance into ``broad.far`` (two
    particles moved by at most the sum of theirs). Blocks of DISPLACEMENT_BLOCK particles
    reduce in parallel, then one thread over the blocks: Taichi keeps no thread-local
    copy of a vector reduced with atomics, so one vector for every particle would have
    the threads take turns on its compare-and-swaps. In a batch of substeps (one
    thread) every loop is serial."""
    P = ti.static(broad.table.point_count)
    B = ti.static(blocks_for(P, DISPLACEMENT_BLOCK))
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for blk in range(B):
        lo = ti.Vector([1e30, 1e30, 1e30], ti.f64)
        hi = ti.Vector([-1e30, -1e30, -1e30], ti.f64)
        for i in range(blk * DISPLACEMENT_BLOCK, ti.min((blk + 1) * DISPLACEMENT_BLOCK, P)):
            p = broad.table.points[i]
            d = ti.cast(x[p] - ref[p], ti.f64)
            lo, hi = ti.min(lo, d), ti.max(hi, d)
            if ti.static(both):
                e = ti.cast(y[p] - ref[p], ti.f64)
                lo, hi = ti.min(lo, e), ti.max(hi, e)
        broad.moved_lo[blk], broad.moved_hi[blk] = lo, hi
    ti.loop_config(serialize=True)
    for _ in range(1):
        lo, hi = broad.moved_lo[0], broad.moved_hi[0]
        for blk in range(1, B):
            lo, hi = ti.min(lo, broad.moved_lo[blk]), ti.max(hi, broad.moved_hi[blk])
        broad.centre[None] = 0.5 * (lo + hi)
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for blk in range(B):
        c = broad.centre[None]
        farthest = ti.cast(0.0, ti.f64)
        for i in range(blk * DISPLACEMENT_BLOCK, ti.min((blk + 1) * DISPLACEMENT_BLOCK, P)):
            p = broad.table.points[i]
            far = (ti.cast(x[p] - ref[p], ti.f64) - c).norm_sqr()
            if ti.static(both):
                far = ti.max(far, (ti.cast(y[p] - ref[p], ti.f64) - c).norm_sqr())
            broad.far[p] = ti.cast(ti.sqrt(far), broad.far.dtype)
            farthest = ti.max(farthest, far)
        broad.moved_far[blk] = farthest
    ti.loop_config(serialize=True)
    for _ in range(1):
        farthest = broad.moved_far[0]
        for blk in range(1, B):
            farthest = ti.max(farthest, broad.moved_far[blk])
        broad.moved_far[0] = farthest                # the kernel returns it from there
    return 2.0 * ti.sqrt(broad.moved_far[0])


@ti.kernel
def _rebuild(broad: ti.template(), search: ti.template(),
             cl: ti.template()) -> ti.types.vector(2, ti.i32):
    """Bin the particles and edge midpoints at x_ref and list the candidate contacts
    within the reach. Returns ``Search.run``'s (rows found, the most a block of queries
    found)."""
    P, E, T = ti.static(cl.table.point_count, cl.table.edge_count, cl.table.triangle_count)
    x = ti.static(broad.x_ref)
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for i in range(P):
        search.points.pos[i] = x[cl.table.points[i]]
    longest = 0.0
    ti.loop_config(serialize=ti.static(serial_count(E)))
    for e in range(E):
        a, b = x[cl.table.edges[e][0]], x[cl.table.edges[e][1]]
        search.edges.pos[e] = 0.5 * (a + b)
        ti.atomic_max(longest, (a - b).norm())
    reach = broad.reach[None]
    cell = ti.max(longest, reach)
    search.points.set_cell(cell)
    search.edges.set_cell(cell)
    search.points.build(P)
    search.edges.build(E)
    # a triangle's box grown by the reach; an edge's by the reach and half the longest
    # edge, since the edges are binned by their midpoints
    grow = reach + 0.5 * longest
    ti.loop_config(serialize=ti.static(serial_count(T)))
    for t in range(T):
        tri = cl.table.triangles[t]
        a, b, c = x[tri[0]], x[tri[1]], x[tri[2]]
        search.lo[t], search.hi[t] = ti.min(a, b, c) - reach, ti.max(a, b, c) + reach
    ti.loop_config(serialize=ti.static(serial_count(E)))
    for e in range(E):
        a, b = x[cl.table.edges[e][0]], x[cl.table.edges[e][1]]
        search.lo[T + e], search.hi[T + e] = ti.min(a, b) - grow, ti.max(a, b) + grow
    return search.run(cl)


@ti.kernel
def _ref_gaps(cl: ti.template(), count: ti.i32, x: ti.template(), out: ti.template()):
    """Each row's gap at x into out."""
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        _, g = gap(cl.ids[c], cl.kind[c], x)
        out[c] = g.norm()


@ti.func
def near(cl, ref_gap, far, c, distance):
    """Whether row c of the proximity list cl (its ``ref_gap``) can be within
    ``distance`` at the positions of the last ``moved`` (or anywhere on its path), whose
    ``far`` that is (module docstring)."""
    ids = cl.ids[c]
    first, second = far[ids[0]], ti.max(far[ids[2]], far[ids[3]])
    if cl.kind[c] == POINT_TRIANGLE:
        second = ti.max(second, far[ids[1]])
    else:
        first = ti.max(first, far[ids[1]])
    return ref_gap[c] - (first + second) <= distance + GAP_ROUNDING


@ti.data_oriented
class BroadPhase(CandidateSearch):
    """The candidate list of one model's self-contact and the positions it was built at.

    Attributes:
        candidates: the ``ContactList``; count: its rows in use.
        ref_gap: each row's gap at x_ref (the module docstring; ``near``).
        skin: the margin of the last build, m (the list holds pairs within thickness +
            skin); rebuilds: how many builds so far.
    """

    def __init__(self, table, inv_mass, particle_count):
        real = runtime.real()
        self.x_ref = ti.Vector.field(3, real, shape=particle_count)
        self.reach = ti.field(real, shape=())
        self.centre = ti.Vector.field(3, ti.f64, shape=())
        moved_blocks = blocks_for(table.point_count, DISPLACEMENT_BLOCK)
        self.moved_lo = ti.Vector.field(3, ti.f64, shape=moved_blocks)
        self.moved_hi = ti.Vector.field(3, ti.f64, shape=moved_blocks)
        self.moved_far = ti.field(ti.f64, shape=moved_blocks)
        self.far = ti.field(real, shape=particle_count)
        super().__init__(table, inv_mass, (PointGrid(table.point_count),
                                           PointGrid(table.edge_count)), self._within)
        self.skin = None
        self.rebuilds = 0
        self.ref_gap = ti.field(real, shape=self.candidates.capacity)
        # count and skin (-1: none) for kernels that run between builds (a batch's)
        self.rows = ti.field(ti.i32, shape=())
        self.skin_now = ti.field(ti.f64, shape=())
        self.skin_now[None] = -1.0

    def _list(self, capacity):
        return ContactList(self.table, self.inv_mass, capacity)

    @ti.func
    def _within(self, ids, kind):
        """Whether the contact ids is within the reach at x_ref. The edge grid reports
        edges whose midpoints lie within the reach and half the longest edge of the
        query's box, most of them farther than the reach: their boxes are compared first
        (the point grid's test is already the point's box against the triangle's)."""
        x = ti.static(self.x_ref)
        reach = self.reach[None]
        close = True
        if kind == EDGE_EDGE:
            a0, a1, b0, b1 = x[ids[0]], x[ids[1]], x[ids[2]], x[ids[3]]
            close = (ti.min(a0, a1) <= ti.max(b0, b1) + reach).all() and \
                (ti.min(b0, b1) <= ti.max(a0, a1) + reach).all()
        within = False
        if close:
            _, g = gap(ids, kind, x)
            within = g.norm() <= reach
        return within

    def moved(self, x, y=None):
        """How far particles moved relative to each other (at most) since the build: from
        x_ref to x, to y, and to anywhere on the straight path from x to y; each
        particle's share into ``far``, for ``near``."""
        y = x if y is None else y
        return _spread(self, self.x_ref, x, y, y is not x)

    def covers(self, x, y=None):
        """Whether the list holds every pair that can be within the thickness at x, at y,
        and on the straight path from x to y."""
        return self.skin is not None and self.moved(x, y) <= self.skin

    def would_cover(self, x0, x1, skin):
        """Whether a list built at x0 with ``skin`` would cover the motion x0 -> x1 (no
        two particles move by more than the skin relative to each other)."""
        return _spread(self, x0, x1, x1, False) <= skin

    def unlisted_distance(self, x):
        """A lower bound on the distance at x of every pair the list leaves out: its
        reach less how far particles moved relative to each other since the build
        (``moved``)."""
        return float(self.reach[None]) - self.moved(x)

    def build(self, x, skin):
        """List the pairs within thickness + skin at x."""
        self.reach[None] = float(self.table.settings["thickness"] + skin)
        # the search reads the copy x_ref, whichever field x is: it compiles once
        self.x_ref.copy_from(x)
        count = self.fit(lambda: _rebuild(self, self.search, self.candidates))
        if self.ref_gap.shape[0] != self.candidates.capacity:
            self.ref_gap = ti.field(runtime.real(), shape=self.candidates.capacity)
        _ref_gaps(self.candidates, count, self.x_ref, self.ref_gap)
        self.skin = float(skin)
        self.rows[None], self.skin_now[None] = count, self.skin
        self.rebuilds += 1

    def invalidate(self):
        """The next ``covers`` is False (the state was set from outside)."""
        self.skin = None
        self.skin_now[None] = -1.0
