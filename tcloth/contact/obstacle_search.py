"""The candidate pairs of a model's cloth and its mesh colliders (``obstacle.py``): each
cloth point's, edge's and triangle's swept box against the hierarchy of each mesh's
triangles (``meshstore``; a rigid mesh's boxes, built once in its own frame, turned into
the world at both ends of the step; a deforming one's refit over both ends), each leaf
triangle's own swept box tested, then its vertices and edges each taken from one triangle
only (``owners``), so no pair is listed twice. The queries run in parallel, each listing
its pairs in its own order (its traversal is serial); ``order`` then sorts the rows by
query (a counting sort), so the rows come in the same order whatever the threads and
their timing (the projection's Gauss-Seidel runs over them in order: a checkpoint's
continuation is bit for bit)."""
import taichi as ti

from .. import runtime
from ..runtime import serial_count
from ..geometry import trimesh
from ..geometry.meshstore import QUERY_WORK, STACK, pose

POINT_TRIANGLE, EDGE_EDGE, VERTEX_TRIANGLE = 0, 1, 2
CHUNK = 32          # raw rows a query reserves at a time
INACTIVE = -1e30    # h of a row without a plane (``obstacle.py``)


@ti.func
def is_cloth(kind, k: ti.template()):
    """Whether vertex k of a row of ``kind`` is the cloth's (ids: point-triangle (cloth
    point, obstacle triangle), edge-edge (cloth edge, obstacle edge), vertex-triangle
    (obstacle vertex, cloth triangle))."""
    out = False
    if kind == POINT_TRIANGLE:
        out = k == 0
    elif kind == EDGE_EDGE:
        out = k < 2
    else:
        out = k > 0
    return out


@ti.func
def _overlap(lo_a, hi_a, lo_b, hi_b):
    return (lo_a <= hi_b).all() and (lo_b <= hi_a).all()


@ti.func
def _world_box(lo, hi, r, c):
    """The world box of the box (lo, hi) of a frame turned by r and moved to c."""
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    wc = r @ centre + c
    wh = ti.abs(r) @ half
    return wc - wh, wc + wh


@ti.data_oriented
class Rows:
    """The pair list's fields, ``capacity`` rows (a larger list is a new one: a kernel
    compiled for one keeps reading its fields): ids (4,), kind, the obstacle triangle
    ``face`` that listed the row, m, h, delta, u (``ObstaclePairs``), ``found``, the rows
    a search found, and the search's rows as found (``raw_ids``, ``raw_kind``,
    ``raw_face``; each one's query ``owner`` and its place ``local`` among that query's
    rows) before ``order`` sorts them."""

    def __init__(self, capacity):
        real = runtime.real()
        self.capacity = capacity
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.kind = ti.field(ti.i32, shape=capacity)
        self.face = ti.field(ti.i32, shape=capacity)
        self.m = ti.Vector.field(3, real, shape=capacity)
        self.h = ti.field(real, shape=capacity)
        self.delta = ti.field(real, shape=capacity)
        self.u = ti.Vector.field(3, real, shape=capacity)
        self.found = ti.field(ti.i32, shape=())
        self.raw_ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.raw_kind = ti.field(ti.i32, shape=capacity)
        self.raw_face = ti.field(ti.i32, shape=capacity)
        self.owner = ti.field(ti.i32, shape=capacity)
        self.local = ti.field(ti.i32, shape=capacity)


@ti.func
def _cloth_box(o: ti.template(), kind, q, grow):
    """The swept box of cloth primitive q of ``kind`` (its vertices' boxes over the step,
    ``cloth_lo``, ``cloth_hi``), grown by ``grow``."""
    lo, hi = ti.Vector([1e30, 1e30, 1e30]), ti.Vector([-1e30, -1e30, -1e30])
    if kind == POINT_TRIANGLE:
        lo, hi = o.cloth_lo[o.points[q]], o.cloth_hi[o.points[q]]
    elif kind == EDGE_EDGE:
        for k in ti.static(range(2)):
            lo, hi = ti.min(lo, o.cloth_lo[o.edges[q][k]]), ti.max(hi, o.cloth_hi[o.edges[q][k]])
    else:
        for k in ti.static(range(3)):
            lo = ti.min(lo, o.cloth_lo[o.triangles[q][k]])
            hi = ti.max(hi, o.cloth_hi[o.triangles[q][k]])
    return lo - grow, hi + grow


@ti.func
def _append(o: ti.template(), rows: ti.template(), slot, ids, kind, face):
    """A row of query ``slot``: its place among the raw rows (the next of the query's
    chunk; a new chunk of ``CHUNK`` reserved where that is used up: one atomic operation
    on the shared count per chunk, not per row) and among the query's rows."""
    if o.next[slot] == o.end[slot]:
        first = ti.atomic_add(rows.found[None], CHUNK)
        o.next[slot], o.end[slot] = first, first + CHUNK
    row = o.next[slot]
    o.next[slot] = row + 1
    local = o.per[slot]
    o.per[slot] = local + 1
    if row < rows.capacity:
        rows.raw_ids[row] = ids
        rows.raw_kind[row] = kind
        rows.raw_face[row] = face
        rows.owner[row] = slot
        rows.local[row] = local


@ti.func
def _emit(o: ti.template(), rows: ti.template(), slot, kind, q, tri, lo, hi, grow):
    """The pairs of cloth primitive q (its box lo, hi) and obstacle triangle ``tri``: a
    loose point's, a rope edge's, or a cloth triangle's with its own vertices and edges
    (each listed by one triangle) and the obstacle's vertices."""
    t = o.store.tris[tri]
    tlo, thi = o.tri_lo[tri], o.tri_hi[tri]
    if _overlap(lo, hi, tlo, thi):
        if kind == POINT_TRIANGLE:
            _append(o, rows, slot, ti.Vector([o.points[q], t[0], t[1], t[2]]), POINT_TRIANGLE,
                    tri)
        elif kind == EDGE_EDGE:
            _edge_pairs(o, rows, slot, o.edges[q], t, tri, lo, hi)
        else:
            c = o.triangles[q]
            for k in ti.static(range(3)):
                if o.own_cv[q][k]:
                    if _overlap(o.cloth_lo[c[k]] - grow, o.cloth_hi[c[k]] + grow, tlo, thi):
                        _append(o, rows, slot, ti.Vector([c[k], t[0], t[1], t[2]]),
                                POINT_TRIANGLE, tri)
                if o.own_ce[q][k]:
                    e = ti.Vector([c[k], c[(k + 1) % 3]])
                    elo = ti.min(o.cloth_lo[e[0]], o.cloth_lo[e[1]])
                    ehi = ti.max(o.cloth_hi[e[0]], o.cloth_hi[e[1]])
                    _edge_pairs(o, rows, slot, e, t, tri, elo - grow, ehi + grow)
                if o.own_v[tri][k]:
                    a = t[k]
                    if _overlap(lo, hi, o.vert_lo[a], o.vert_hi[a]):
                        _append(o, rows, slot, ti.Vector([a, c[0], c[1], c[2]]),
                                VERTEX_TRIANGLE, tri)


@ti.func
def _edge_pairs(o: ti.template(), rows: ti.template(), slot, e, t, tri, lo, hi):
    """Cloth edge e (its box lo, hi) against the edges obstacle triangle ``tri`` (vertices
    t) lists."""
    for k in ti.static(range(3)):
        if o.own_e[tri][k]:
            a, b = t[k], t[(k + 1) % 3]
            if _overlap(lo, hi, ti.min(o.vert_lo[a], o.vert_lo[b]),
                        ti.max(o.vert_hi[a], o.vert_hi[b])):
                _append(o, rows, slot, ti.Vector([e[0], e[1], a, b]), EDGE_EDGE, tri)


@ti.func
def _query(o: ti.template(), rows: ti.template(), slot, kind, q, lo, hi, t0, dt, grow):
    """Every obstacle triangle whose swept box meets (lo, hi): ``_emit``."""
    for m in range(o.store.meshes.shape[0]):
        if not o.certified[m]:
            continue
        info = o.store.meshes[m]
        col = o.table.data[o.mesh_row[m]]
        r0, c0 = pose(col, t0)
        r1, c1 = pose(col, t0 + dt)
        if info[6]:
            r0, r1 = ti.Matrix.identity(float, 3), ti.Matrix.identity(float, 3)
            c0, c1 = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3)
        # a mesh still over the step: the query's box in its frame, the nodes' as built
        still = (r0 == r1).all() and (c0 == c1).all()
        qlo, qhi = _world_box(lo - c0, hi - c0, r0.transpose(), ti.Vector.zero(float, 3))
        leaves, node0, tri0, tris = info[4], info[3], info[0], info[1]
        stack = ti.Vector([0] * STACK)
        stack[0], top = 1, 1
        while top > 0:
            top -= 1
            k = stack[top]
            nlo, nhi = o.store.node_lo[node0 + k], o.store.node_hi[node0 + k]
            meets = False
            if still:
                meets = _overlap(qlo, qhi, nlo, nhi)
            else:
                a_lo, a_hi = _world_box(nlo, nhi, r0, c0)
                b_lo, b_hi = _world_box(nlo, nhi, r1, c1)
                meets = _overlap(lo, hi, ti.min(a_lo, b_lo), ti.max(a_hi, b_hi))
            if (nlo <= nhi).all() and meets:
                if k >= leaves:
                    for j in range(trimesh.LEAF):
                        tri = (k - leaves) * trimesh.LEAF + j
                        if tri < tris:
                            _emit(o, rows, slot, kind, q, tri0 + tri, lo, hi, grow)
                else:
                    stack[top], stack[top + 1] = 2 * k + 1, 2 * k
                    top += 2


@ti.kernel
def search(o: ti.template(), rows: ti.template(), x0: ti.template(), x1: ti.template(),
           grow: float, t0: float, dt: float) -> ti.i32:
    """The rows of the motion x0 -> x1 (boxes grown by ``grow``) as found (``order``
    sorts them); returns how many raw rows the queries took (their chunks: more than the
    capacity: search again with more)."""
    rows.found[None] = 0
    P, E, T = ti.static(o.counts)
    for q in range(P + E + T):
        o.per[q], o.next[q], o.end[q] = 0, 0, 0
    ti.loop_config(serialize=ti.static(serial_count(x0.shape[0])))
    for i in range(x0.shape[0]):
        o.cloth_lo[i], o.cloth_hi[i] = ti.min(x0[i], x1[i]), ti.max(x0[i], x1[i])
    ti.loop_config(serialize=ti.static(serial_count((P + E + T) * QUERY_WORK)))
    for q in range(P + E + T):
        kind, item = POINT_TRIANGLE, q
        if q >= P + E:
            kind, item = VERTEX_TRIANGLE, q - P - E
        elif q >= P:
            kind, item = EDGE_EDGE, q - P
        lo, hi = _cloth_box(o, kind, item, grow)
        _query(o, rows, q, kind, item, lo, hi, t0, dt, grow)
        for r in range(o.next[q], ti.min(o.end[q], rows.capacity)):
            rows.owner[r] = -1      # the rest of its last chunk: no row
    return rows.found[None]


@ti.kernel
def obstacle_boxes(o: ti.template()):
    """Each obstacle vertex's and triangle's box over the step (xo0 -> xo1)."""
    ti.loop_config(serialize=ti.static(serial_count(o.xo0.shape[0])))
    for i in range(o.xo0.shape[0]):
        o.vert_lo[i], o.vert_hi[i] = ti.min(o.xo0[i], o.xo1[i]), ti.max(o.xo0[i], o.xo1[i])
    ti.loop_config(serialize=ti.static(serial_count(o.tri_lo.shape[0])))
    for f in range(o.tri_lo.shape[0]):
        t = o.store.tris[f]
        o.tri_lo[f] = ti.min(o.vert_lo[t[0]], o.vert_lo[t[1]], o.vert_lo[t[2]])
        o.tri_hi[f] = ti.max(o.vert_hi[t[0]], o.vert_hi[t[1]], o.vert_hi[t[2]])


@ti.kernel
def order(o: ti.template(), rows: ti.template(), found: ti.i32) -> ti.i32:
    """The rows of a search (``found`` raw rows) sorted by query, each query's in the
    order it listed them (a counting sort: where each query's rows start, then every row
    to its place); returns how many there are."""
    for _ in range(1):          # one thread: each query's start, in order
        start = 0
        for q in range(o.per.shape[0]):
            o.start[q] = start
            start += o.per[q]
        o.total[None] = start
    ti.loop_config(serialize=ti.static(serial_count(rows.capacity)))
    for r in range(found):
        if rows.owner[r] >= 0:
            place = o.start[rows.owner[r]] + rows.local[r]
            rows.ids[place] = rows.raw_ids[r]
            rows.kind[place] = rows.raw_kind[r]
            rows.face[place] = rows.raw_face[r]
    return o.total[None]


