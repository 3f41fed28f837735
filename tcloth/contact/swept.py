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

The boxes are binned in uniform cells hashed into a table, each point's and edge's box
into every cell it overlaps (``hashgrid.BoxGrid``), and the candidate search
(``search.py``) runs each triangle's and edge's box over them; a pair found in several
cells is kept only in the first cell of their overlap, so each pair is listed once. The
cell is the larger of the longest edge, T and a third of the longest path, so a box spans
at most a few cells a side.

The guard then moves end positions off their paths (its projection, the colliders'
sweep), mostly back toward where they started, and a solver's iterates wander about the
predicted end it was searched for. The boxes are grown by a margin besides, so one search
serves every motion whose ends stay within the margin of the box of each particle's
searched path (``SweptSearch.holds``), and a step searches again only where a particle
left it.

A search for a solver whose iterates stay near the predicted end (``near``: projective
dynamics', whose last iterate ended within 1.9 mm of its first on the 64 x 64 fold, T
being 3.75 mm) keeps only the pairs that can come within T on a motion it holds
(``SweptSearch._may_meet``), and holds a motion only where each particle starts within
the margin of its searched start (``origin``) and ends within it of its searched end
(``anchor``). Along the straight path between them a vertex pair's relative displacement
from the start stays within the searched one's plus twice the margin, and a pair's gap
closes by at most its vertex pairs' longest relative displacement
(``guard.relative_path``), so a pair whose gap at the start less the searched closing
stays above T plus twice the margin is left out. Swept boxes alone listed about 500,000
pairs on that fold, most of them neighbours in one layer that move together; the near
search lists a tenth to a third of them (``docs/contact.md``). XPBD's and VBD's iterates
move farther from the prediction: they keep the boxes (a near search with its stricter
``holds`` searched again nearly every iteration).
"""
import taichi as ti

from .. import runtime
from ..runtime import serial_count
from .broad import GAP_ROUNDING
from .candidates import ContactList, gap
from .guard import relative_path
from .hashgrid import BoxGrid
from .search import CandidateSearch

# each grid's entries at first, per point or edge (a box spans a few cells a side): more
# is made again larger, and the search compiles again (``search.SLOTS_PER_QUERY``)
ENTRIES_PER_ITEM = 32


def _box_grids(table, capacity):
    """The grids of the points' and the edges' swept boxes, ``capacity`` entries each."""
    return BoxGrid(table.point_count, capacity), BoxGrid(table.edge_count, capacity)


@ti.data_oriented
class SweptSearch(CandidateSearch):
    """The swept-box candidates of one step (module docstring): ``candidates`` (a
    ``ContactList``) and ``count``; ``origin`` and ``anchor`` the start and end positions,
    ``margin`` the margin it was searched with; ``filtered`` 1 after a near search and
    ``reach`` the thickness plus twice the margin, for ``_may_meet``."""

    def __init__(self, table, inv_mass):
        self.origin, self.anchor = (ti.Vector.field(3, inv_mass.dtype, shape=inv_mass.shape[0])
                                    for _ in range(2))
        self.margin = 0.0
        self.reach = ti.field(runtime.real(), shape=())
        self.filtered = ti.field(ti.i32, shape=())
        super().__init__(table, inv_mass,
                         _box_grids(table, ENTRIES_PER_ITEM * (table.point_count + table.edge_count)),
                         self._may_meet)

    @ti.func
    def _may_meet(self, ids, kind):
        """Whether contact ids can come within the thickness on a motion a near search
        holds (module docstring); every pair for the others."""
        keep = True
        if self.filtered[None]:
            _, g = gap(ids, kind, self.origin)
            closing = relative_path(ids, kind, self.origin, self.anchor)
            keep = g.norm() - closing <= self.reach[None] + GAP_ROUNDING
        return keep

    def _list(self, capacity):
        return ContactList(self.table, self.inv_mass, capacity)

    def _regrid(self, entries):
        self.grids = _box_grids(self.table, entries)

    def holds(self, x0, x1):
        """Whether the candidates still hold every pair that can come within the thickness
        on the motion x0 -> x1 (module docstring): both ends within the margin of the box
        of each particle's searched path (``origin`` -> ``anchor``), or after a near
        search each particle's start within the margin of ``origin`` and its end within
        it of ``anchor``."""
        if self.filtered[None]:
            return float(departure(self.table.points, self.origin, self.anchor, x0,
                                   x1)) <= self.margin
        return max(float(excess(self.table.points, self.origin, self.anchor, x))
                   for x in (x0, x1)) <= self.margin

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
def sweep_search(search: ti.template(), cl: ti.template(), x0: ti.template(),
                 x1: ti.template(), thickness: float, margin: float,
                 cell: float) -> ti.types.vector(4, ti.i32):
    """List the swept-box candidates of the step x0 -> x1, boxes grown by ``margin``
    besides, with ``search`` into ``cl``. Returns ``Search.run``'s (rows found, the most a
    block of queries found), then the entries the point and the edge grid needed."""
    P, E, T = ti.static(search.table.point_count, search.table.edge_count,
                        search.table.triangle_count)
    # the boxes are grown by half the thickness each (and the margin): two meet where the
    # primitives can come within the thickness
    half = ti.cast(0.5 * thickness + margin, ti.f32)
    search.points.set_cell(cell)
    search.edges.set_cell(cell)
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for i in range(P):
        p = search.table.points[i]
        lo, hi = _box(x0, x1, ti.Vector([p]), half)
        search.points.lo[i], search.points.hi[i] = lo, hi
    ti.loop_config(serialize=ti.static(serial_count(E)))
    for e in range(E):
        lo, hi = _box(x0, x1, search.table.edges[e], half)
        search.edges.lo[e], search.edges.hi[e] = lo, hi
        search.lo[T + e], search.hi[T + e] = lo, hi
    ti.loop_config(serialize=ti.static(serial_count(T)))
    for t in range(T):
        search.lo[t], search.hi[t] = _box(x0, x1, search.table.triangles[t], half)
    point_entries = search.points.build(P)
    edge_entries = search.edges.build(E)
    found = search.run(cl)
    return ti.Vector([found[0], found[1], point_entries, edge_entries])


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


@ti.kernel
def departure(points: ti.template(), origin: ti.template(), anchor: ti.template(),
              x0: ti.template(), x1: ti.template()) -> ti.f64:
    """The farthest a particle of ``points`` starts from its ``origin`` or ends from its
    ``anchor`` on the motion x0 -> x1 (m)."""
    most = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial_count(points.shape[0])))
    for i in range(points.shape[0]):
        p = points[i]
        out = ti.max((x0[p] - origin[p]).norm(), (x1[p] - anchor[p]).norm())
        ti.atomic_max(most, ti.cast(out, ti.f64))
    return most


def search_step(swept, x0, x1, thickness, margin, near=False):
    """Fill ``swept.candidates`` (a ``SweptSearch``) with the step's swept-box candidates,
    boxes grown by ``margin`` (m) besides, less those that cannot meet where ``near``
    (module docstring); returns their number (also ``swept.count``)."""
    # the search reads copies, whichever fields x0 and x1 are: its kernels compile once
    swept.origin.copy_from(x0)
    swept.anchor.copy_from(x1)
    x0, x1, table = swept.origin, swept.anchor, swept.table
    path = float(longest_path(table.points, x0, x1))
    cell = max(float(longest_edge(table, x0)), thickness + 2.0 * margin, path / 3.0, 1e-9)
    swept.margin = margin
    swept.reach[None] = thickness + 2.0 * margin
    swept.filtered[None] = int(near)
    return swept.fit(lambda: sweep_search(swept.search, swept.candidates, swept.origin,
                                          swept.anchor, thickness, margin, cell))
