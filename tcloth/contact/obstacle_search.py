"""The candidate pairs of a model's cloth and its mesh colliders (``obstacle.py``): each
cloth point's, edge's and triangle's swept box against the hierarchy of each mesh's
triangles (``meshstore``; a rigid mesh's boxes, built once in its own frame, turned into
the world at both ends of the step; a deforming one's refit over both ends), each leaf
triangle's own swept box tested, then its vertices and edges each taken from one triangle
only (``owners``), so no pair is listed twice. The queries run on one thread in order, so
the rows come in the same order whatever the threads (a checkpoint's continuation is bit
for bit)."""
import taichi as ti

from .. import runtime
from ..geometry import trimesh
from ..geometry.meshstore import STACK, pose

POINT_TRIANGLE, EDGE_EDGE, VERTEX_TRIANGLE = 0, 1, 2


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
    compiled for one keeps reading its fields): ids (4,), kind, m, h, delta, u
    (``ObstaclePairs``), and ``found``, the rows a search found."""

    def __init__(self, capacity):
        real = runtime.real()
        self.capacity = capacity
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.kind = ti.field(ti.i32, shape=capacity)
        self.m = ti.Vector.field(3, real, shape=capacity)
        self.h = ti.field(real, shape=capacity)
        self.delta = ti.field(real, shape=capacity)
        self.u = ti.Vector.field(3, real, shape=capacity)
        self.found = ti.field(ti.i32, shape=())


@ti.func
def _swept(x0, x1, i, lo, hi):
    return ti.min(lo, x0[i], x1[i]), ti.max(hi, x0[i], x1[i])


@ti.func
def _cloth_box(o: ti.template(), kind, q, x0, x1, grow):
    """The swept box of cloth primitive q of ``kind``, grown by ``grow``."""
    lo, hi = ti.Vector([1e30, 1e30, 1e30]), ti.Vector([-1e30, -1e30, -1e30])
    if kind == POINT_TRIANGLE:
        lo, hi = _swept(x0, x1, o.points[q], lo, hi)
    elif kind == EDGE_EDGE:
        for k in ti.static(range(2)):
            lo, hi = _swept(x0, x1, o.edges[q][k], lo, hi)
    else:
        for k in ti.static(range(3)):
            lo, hi = _swept(x0, x1, o.triangles[q][k], lo, hi)
    return lo - grow, hi + grow


@ti.func
def _append(rows: ti.template(), ids, kind):
    row = ti.atomic_add(rows.found[None], 1)
    if row < rows.capacity:
        rows.ids[row] = ids
        rows.kind[row] = kind


@ti.func
def _emit(o: ti.template(), rows: ti.template(), kind, q, tri, lo, hi, x0, x1, grow):
    """The pairs of cloth primitive q (its box lo, hi) and obstacle triangle ``tri``: a
    loose point's, a rope edge's, or a cloth triangle's with its own vertices and edges
    (each listed by one triangle) and the obstacle's vertices."""
    t = o.store.tris[tri]
    tlo, thi = _swept(o.xo0, o.xo1, t[0], o.xo0[t[0]], o.xo0[t[0]])
    tlo, thi = _swept(o.xo0, o.xo1, t[1], tlo, thi)
    tlo, thi = _swept(o.xo0, o.xo1, t[2], tlo, thi)
    if _overlap(lo, hi, tlo, thi):
        if kind == POINT_TRIANGLE:
            _append(rows, ti.Vector([o.points[q], t[0], t[1], t[2]]), POINT_TRIANGLE)
        elif kind == EDGE_EDGE:
            _edge_pairs(o, rows, o.edges[q], t, tri, lo, hi)
        else:
            c = o.triangles[q]
            for k in ti.static(range(3)):
                if o.own_cv[q][k]:
                    plo, phi = _swept(x0, x1, c[k], x0[c[k]], x0[c[k]])
                    if _overlap(plo - grow, phi + grow, tlo, thi):
                        _append(rows, ti.Vector([c[k], t[0], t[1], t[2]]), POINT_TRIANGLE)
                if o.own_ce[q][k]:
                    e = ti.Vector([c[k], c[(k + 1) % 3]])
                    elo, ehi = _swept(x0, x1, e[0], x0[e[0]], x0[e[0]])
                    elo, ehi = _swept(x0, x1, e[1], elo, ehi)
                    _edge_pairs(o, rows, e, t, tri, elo - grow, ehi + grow)
                if o.own_v[tri][k]:
                    a = t[k]
                    if _overlap(lo, hi, ti.min(o.xo0[a], o.xo1[a]), ti.max(o.xo0[a], o.xo1[a])):
                        _append(rows, ti.Vector([a, c[0], c[1], c[2]]), VERTEX_TRIANGLE)


@ti.func
def _edge_pairs(o: ti.template(), rows: ti.template(), e, t, tri, lo, hi):
    """Cloth edge e (its box lo, hi) against the edges obstacle triangle ``tri`` (vertices
    t) lists."""
    for k in ti.static(range(3)):
        if o.own_e[tri][k]:
            a, b = t[k], t[(k + 1) % 3]
            blo, bhi = _swept(o.xo0, o.xo1, a, o.xo0[a], o.xo0[a])
            blo, bhi = _swept(o.xo0, o.xo1, b, blo, bhi)
            if _overlap(lo, hi, blo, bhi):
                _append(rows, ti.Vector([e[0], e[1], a, b]), EDGE_EDGE)


@ti.func
def _query(o: ti.template(), rows: ti.template(), kind, q, lo, hi, t0, dt, x0, x1, grow):
    """Every obstacle triangle whose swept box meets (lo, hi): ``_emit``."""
    for m in range(o.store.meshes.shape[0]):
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
                            _emit(o, rows, kind, q, tri0 + tri, lo, hi, x0, x1, grow)
                else:
                    stack[top], stack[top + 1] = 2 * k + 1, 2 * k
                    top += 2


@ti.kernel
def search(o: ti.template(), rows: ti.template(), x0: ti.template(), x1: ti.template(),
           grow: float, t0: float, dt: float) -> ti.i32:
    """The rows of the motion x0 -> x1 (boxes grown by ``grow``); returns how many were
    found (more than the capacity: search again with more)."""
    rows.found[None] = 0
    P, E, T = ti.static(o.counts)
    ti.loop_config(serialize=True)
    for q in range(P + E + T):
        kind, item = POINT_TRIANGLE, q
        if q >= P + E:
            kind, item = VERTEX_TRIANGLE, q - P - E
        elif q >= P:
            kind, item = EDGE_EDGE, q - P
        lo, hi = _cloth_box(o, kind, item, x0, x1, grow)
        _query(o, rows, kind, item, lo, hi, t0, dt, x0, x1, grow)
    return rows.found[None]


