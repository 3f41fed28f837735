"""Mesh colliders in the guard: the pairs of cloth and obstacle primitives, kept apart by
separating planes as the cloth's own pairs are (``guard.py``), with the obstacle side
immovable.

An obstacle's vertices move on straight lines over a step from their positions at t0 to
those at t0 + dt (a rigid one's pose at both ends, a deforming one's frames), the cloth's
from x0 to x1. Three kinds of pairs can cross: a cloth point and an obstacle triangle
(``POINT_TRIANGLE``), a cloth edge and an obstacle edge (``EDGE_EDGE``: a table's rim under
a draped cloth), and an obstacle vertex and a cloth triangle (``VERTEX_TRIANGLE``: a
corner poking up into the cloth). A pair separated at the step's start by its gap D0
along the unit normal m of its closest points (from the obstacle's side to the cloth's)
stays separated along the whole step if at its end every cloth vertex a of it and every
obstacle vertex b keep m . (x_a - x_b) >= delta (the function min_a m . x_a - max_b m . x_b
is concave on straight paths): with the obstacle's ends known before the step, that is
one half-space a cloth vertex, m . x_a >= h, h = max_b m . xo1_b + delta. A point-triangle
pair's m is the obstacle's surface normal at the point (or that of the edge or corner
nearest it): delta = min(T, max(D0, T / 4)), the contact law's offset T, or the start's
gap D0 where the pair began nearer (no push away), so a landing cloth is held where the
contact law rests it (held at T / 4 it lay within the law's offset, whose penalty then
held energy the step never gave: a 32 x 32 cloth landing flat on a mesh box, 6.9 J
against the scene's 0.75 J). An edge-edge or vertex-triangle pair's m is a gap direction
between primitives that can lie far from the surface's normal (a cloth triangle's normal
over an obstacle's corner, the common normal of two edges), and every cloth vertex of the
pair must meet it: held at T along it, a cloth landing at 10 m/s on a mesh sphere was
pushed sideways by up to 5.8 cm (strain 2.3); those pairs keep delta = T / 4, what the
guarantee needs (strain 0.67). ``project`` moves each cloth vertex
onto its half-spaces (Gauss-Seidel over the rows, in order) and removes its normal
velocity into the obstacle (relative to the obstacle's at the pair): an inelastic
contact, which adds no energy. A vertex no projection can satisfy (squeezed between two
sides of a closing obstacle) is carried with the obstacle by ``carry``, the fail-safe:
moved as the obstacle around it moves, it crosses none of its triangles.

The candidates (``obstacle_search.py``): the pairs whose swept boxes, grown by half the
thickness and a margin, meet. A list serves while the cloth stays within its margin of the
boxes it was searched with and a moving obstacle is where it was searched (``holds``).
"""
import time

import numpy as np
import taichi as ti

from .. import runtime
from ..geometry.meshstore import pose
from ..geometry.proximity import contact_weights
from ..runtime import serial_count
from ..scene.meshcollider import moves
from .hold import Hold
from .obstacle_search import (EDGE_EDGE, INACTIVE, POINT_TRIANGLE, VERTEX_TRIANGLE, Rows,
                              is_cloth, obstacle_boxes, order, search)
from .swept import excess
FLOOR = 0.25        # pairs end a step at least this fraction of the thickness apart
LEAST_GAP = 1e-6    # m: a pair closer than this at the step's start has no normal
SLACK = 1e-3        # a violation below this fraction of FLOOR T is none
ADVANCES = 24       # conservative advancement's steps before it takes the plane where it is
ADVANCE_SLACK = 0.05  # a gap within this fraction above delta has come down to it
FLAT = 1e-6         # faces whose unit normals' dot is within this of 1 are in one plane
# rows at first per cloth query: more is made again larger (twice what a search found) and
# every kernel that reads them compiles again (breathing's blanket needed 16 to 32)
ROWS_PER_QUERY = 32


def _owners(triangles):
    """(F, 3) int flags: corner k of face f is where vertex t[f, k] is first listed, and
    edge k (corner k to k + 1) of face f is where that edge is first listed."""
    t = np.asarray(triangles, dtype=np.int64)
    flat = t.ravel()
    _, first = np.unique(flat, return_index=True)
    own_v = np.zeros(flat.size, np.int32)
    own_v[first] = 1
    edges = np.sort(np.stack([t, np.roll(t, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    _, first = np.unique(edges, axis=0, return_index=True)
    own_e = np.zeros(len(edges), np.int32)
    own_e[first] = 1
    return own_v.reshape(-1, 3), own_e.reshape(-1, 3)


def _flat(vertices, triangles):
    """(F, 3) bool flags as ``_owners``'s: corner k of face f is a vertex and edge k an
    edge inside a flat patch (each edge in exactly two faces whose unit normals agree
    within FLAT; a vertex whose every edge is such). Such an edge or vertex needs no
    pairs: a cloth primitive that starts clear of a flat patch first crosses it through
    one of its faces or its border, and the patch's faces and border have theirs; their
    common normals (two edges in the top of a platter, a cloth triangle over a vertex in
    it) can tilt far from the surface's and would push the cloth sideways."""
    t = np.asarray(triangles, dtype=np.int64)
    v = np.asarray(vertices, dtype=np.float64)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    edges = np.sort(np.stack([t, np.roll(t, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    _, which, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    which = which.ravel()
    faces = np.repeat(np.arange(len(t)), 3)
    by_edge = np.argsort(which, kind="stable")      # each edge's faces side by side
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    shared = counts == 2
    f0, f1 = faces[by_edge[start[shared]]], faces[by_edge[start[shared] + 1]]
    flat = np.zeros(len(counts), bool)
    flat[shared] = np.einsum("ij,ij->i", n[f0], n[f1]) >= 1.0 - FLAT
    flat_e = flat[which]
    flat_v = np.ones(len(v), bool)
    np.logical_and.at(flat_v, edges.ravel(), np.repeat(flat_e, 2))
    return flat_v[t], flat_e.reshape(-1, 3)


@ti.data_oriented
class ObstaclePairs:
    """The pairs of a model's cloth and its mesh colliders (module docstring).

    Attributes:
        points, edges, triangles: the cloth's primitives (``topology.contact_topology``).
        xo0, xo1: every obstacle vertex in the world at the step's ends.
        rows: a ``Rows`` (``count`` in use): the primitives' ids (cloth particles;
            obstacle vertices of ``xo0``), the kind, the plane's normal m toward the cloth,
            its level h for the cloth's vertices, the obstacle's velocity u there.
    """

    def __init__(self, model, topology, thickness):
        real = runtime.real()
        self.table, self.store = model.colliders, model.colliders.meshes
        self.inv_mass = model.inv_mass
        self.thickness = thickness
        # the meshes on this path (``collider_table``: the others are distance fields)
        self.certified = _ints([int(m in self.table.certified)
                                for m in range(len(self.table.mesh_colliders))], ())
        self.static = all(not moves(self.table.mesh_colliders[m]) for m in self.table.certified)
        # a cloth triangle's query lists the pairs of its own vertices and edges too (each
        # from the first triangle that has it: ``own_cv``, ``own_ce``); points and edges
        # in no triangle (loose particles, ropes) have queries of their own
        triangles = np.asarray(topology["triangles"], dtype=np.int64).reshape(-1, 3)
        edges = np.asarray(topology["edges"], dtype=np.int64).reshape(-1, 2)
        own_cv, own_ce = _owners(triangles) if len(triangles) else (np.zeros((0, 3)),) * 2
        lonely_points = np.setdiff1d(np.arange(model.particle_count), triangles)
        in_triangles = {tuple(e) for e in np.sort(np.concatenate(
            [triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)}
        lonely_edges = np.array([e for e in edges if tuple(np.sort(e)) not in in_triangles],
                                dtype=np.int64).reshape(-1, 2)
        self.counts = (len(lonely_points), len(lonely_edges), len(triangles))
        self.points = _ints(lonely_points, ())
        self.edges = _ints(lonely_edges, (2,))
        self.triangles = _ints(triangles, (3,))
        self.own_cv, self.own_ce = _ints(own_cv, (3,)), _ints(own_ce, (3,))
        self.every_point = _ints(np.arange(model.particle_count), ())
        # each query's rows (``obstacle_search``): how many, and where they start
        self.per = ti.field(ti.i32, shape=max(sum(self.counts), 1))
        self.start = ti.field(ti.i32, shape=max(sum(self.counts), 1))
        self.next = ti.field(ti.i32, shape=max(sum(self.counts), 1))   # its chunk's next
        self.end = ti.field(ti.i32, shape=max(sum(self.counts), 1))    # and end raw row
        self.total = ti.field(ti.i32, shape=())
        n_obstacle = self.store.va.shape[0]
        self.xo0 = ti.Vector.field(3, real, shape=n_obstacle)
        self.xo1 = ti.Vector.field(3, real, shape=n_obstacle)
        # boxes over the step (``obstacle_search``): the obstacle's vertices and triangles,
        # the cloth's vertices
        self.vert_lo = ti.Vector.field(3, real, shape=n_obstacle)
        self.vert_hi = ti.Vector.field(3, real, shape=n_obstacle)
        self.tri_lo = ti.Vector.field(3, real, shape=self.store.tris.shape[0])
        self.tri_hi = ti.Vector.field(3, real, shape=self.store.tris.shape[0])
        self.cloth_lo = ti.Vector.field(3, real, shape=model.particle_count)
        self.cloth_hi = ti.Vector.field(3, real, shape=model.particle_count)
        # each obstacle vertex's collider row
        row_of = np.zeros(n_obstacle, np.int32)
        own_v, own_e, flat = [], [], []
        for k, r in zip(self.table.mesh_rows, self.store.records):
            row_of[r["vert_first"]:r["vert_first"] + len(r["v"])] = k
            v, e = _owners(r["tris"])
            flat_v = flat_e = np.zeros(v.shape, bool)
            if not r["deforming"]:
                flat_v, flat_e = _flat(r["v"], r["tris"])
            own_v.append(v * ~flat_v)       # no pairs of a flat patch's inner corners, edges
            own_e.append(e * ~flat_e)
            flat.append((flat_e << np.arange(3)).sum(1) + (flat_v << np.arange(3, 6)).sum(1))
        self.row_of = _ints(row_of, ())
        self.mesh_row = _ints(self.table.mesh_rows, ())
        self.own_v = _ints(np.concatenate(own_v), (3,))
        self.own_e = _ints(np.concatenate(own_e), (3,))
        # each triangle's edges (bit k: corner k to k + 1) and corners (bit 3 + k) inside a
        # flat patch (``_flat``; none on a deforming mesh)
        self.flat = _ints(np.concatenate(flat), ())
        self.origin = ti.Vector.field(3, real, shape=model.particle_count)
        self.anchor = ti.Vector.field(3, real, shape=model.particle_count)
        self.margin = 0.0
        self.searched = None        # the step (t0, dt) a moving obstacle was searched for
        self.rows = Rows(ROWS_PER_QUERY * sum(self.counts) + 64)
        self.count = 0
        self.searches = 0
        self.search_seconds = 0.0     # wall time of the searches (their kernels waited for)
        self.current = False          # the planes are those of the motion as it now is
        self.hold = Hold(model)       # the planes inside a solve (``hold.py``)

    # -- the step ------------------------------------------------------------------------
    def begin(self, x0, x1, t0, dt, margin):
        """The obstacle at both ends of the step (once for good where it is still), the
        candidates of the motion x0 -> x1 (searched again where the list does not hold
        it) and their planes."""
        if not (self.static and self.searched is not None):
            _positions(self, t0, dt)
            obstacle_boxes(self)
        self.cover(x0, x1, t0, dt, margin)

    def cover(self, x0, x1, t0, dt, margin):
        """Make the rows hold the motion x0 -> x1 (search again if they do not) and their
        planes that motion's."""
        if not self.holds(x0, x1, t0, dt):
            start = time.perf_counter()
            self.searches += 1
            self.origin.copy_from(x0)
            self.anchor.copy_from(x1)
            self.margin = margin
            self.searched = (t0, dt)
            while True:
                found = int(search(self, self.rows, x0, x1, 0.5 * self.thickness + margin,
                                    t0, dt))
                if found <= self.rows.capacity:
                    break
                self.rows = Rows(2 * found)
            self.count = int(order(self, self.rows, found))
            self.search_seconds += time.perf_counter() - start
        _planes(self, self.rows, self.count, x0, x1, self.thickness, dt)

    def holds(self, x0, x1, t0, dt):
        """Whether the rows hold every pair that can come within the thickness on the
        motion x0 -> x1 of this step: the cloth within the margin of the searched boxes
        and the obstacle where it was searched (a static one always is)."""
        if self.searched is None or not (self.static or self.searched == (t0, dt)):
            return False
        return max(float(excess(self.every_point, self.origin, self.anchor, x))
                   for x in (x0, x1)) <= self.margin

    def project(self, x0, x1, v1, stop_normal, t0, dt, sweeps, rounds):
        """Rounds of: the rows and planes of the motion as it now is (``cover``), then
        Gauss-Seidel sweeps of the half-spaces on the cloth's vertices until one corrects
        nothing (at most ``sweeps``), until a round corrects nothing (at most
        ``rounds``). Returns the corrections; ``current`` says whether the planes are
        those of the motion it leaves (its last round corrected nothing)."""
        total = 0
        for round_ in range(rounds):
            if round_:
                self.cover(x0, x1, t0, dt, self.margin)
            corrected, _ = _project(self, self.rows, self.count, x0, x1, v1, stop_normal, dt,
                                    sweeps)
            total += int(corrected)
            self.current = not corrected
            if not corrected:
                break
        return total

    def violations(self, x1):
        return int(_violations(self, self.rows, self.count, x1))

    def carry(self, x0, x1, v1, t0, dt, rounds=8):
        """The fail-safe: the free cloth vertices of violated rows moved with the obstacle
        from their start (as its pose moves them; a deforming one's by the row's
        obstacle points' motion), rounds until no row is violated. Returns the
        vertices carried."""
        carried = 0
        for _ in range(rounds):
            moved = int(_carry(self, self.rows, self.count, x0, x1, v1, t0, dt))
            carried += moved
            if not moved:
                break
        return carried


def _ints(values, inner):
    values = np.asarray(values, dtype=np.int32)
    rows = max(len(values), 1)
    f = ti.field(ti.i32, shape=rows) if not inner else ti.Vector.field(inner[0], ti.i32,
                                                                       shape=rows)
    if len(values):
        f.from_numpy(values)
    return f


@ti.kernel
def _positions(o: ti.template(), t0: float, dt: float):
    """xo0, xo1: the obstacle's vertices in the world at t0 and t0 + dt."""
    ti.loop_config(serialize=ti.static(serial_count(o.xo0.shape[0])))
    for i in range(o.xo0.shape[0]):
        col = o.table.data[o.row_of[i]]
        if o.store.meshes[col.mesh][6]:
            o.xo0[i], o.xo1[i] = o.store.va[i], o.store.vb[i]
        else:
            r0, c0 = pose(col, t0)
            r1, c1 = pose(col, t0 + dt)
            o.xo0[i], o.xo1[i] = r0 @ o.store.va[i] + c0, r1 @ o.store.va[i] + c1


@ti.func
def _gap(ids, kind, x0, x1, xo0, xo1, s):
    """(gap vector from the obstacle's side to the cloth's, alpha) of a row with every
    vertex a fraction s along its path."""
    y = [ti.Vector.zero(float, 3) for _ in ti.static(range(4))]
    for k in ti.static(range(4)):
        if is_cloth(kind, k):
            y[k] = x0[ids[k]] + s * (x1[ids[k]] - x0[ids[k]])
        else:
            y[k] = xo0[ids[k]] + s * (xo1[ids[k]] - xo0[ids[k]])
    alpha = contact_weights(1 if kind == EDGE_EDGE else 0, y[0], y[1], y[2], y[3])
    g = alpha[0] * y[0] + alpha[1] * y[1] + alpha[2] * y[2] + alpha[3] * y[3]
    if kind == VERTEX_TRIANGLE:
        g = -g
    return g, alpha


@ti.func
def _closing(ids, kind, x0, x1, xo0, xo1):
    """The most the row's gap can close over the step: the longest relative displacement
    of a cloth and an obstacle vertex of it (the gap is a convex combination of such
    differences)."""
    most = 0.0
    for a in ti.static(range(4)):
        if is_cloth(kind, a):
            for b in ti.static(range(4)):
                if not is_cloth(kind, b):
                    most = ti.max(most, ((x1[ids[a]] - x0[ids[a]])
                                         - (xo1[ids[b]] - xo0[ids[b]])).norm())
    return most


@ti.kernel
def _planes(o: ti.template(), rows: ti.template(), count: ti.i32, x0: ti.template(),
            x1: ti.template(), thickness: float, dt: float):
    """Each row's plane for the motion x0 -> x1 (module docstring): the first fraction s
    of the step at which its gap comes down to a quarter of the thickness (FLOOR T),
    found by conservative advancement (the gap closes by at most ``_closing`` over the
    whole step, so moving s on by (gap - FLOOR T) / closing cannot pass it). A row whose
    gap stays above that all along has none (h = INACTIVE): its path crosses nothing, and
    a cloth sliding over a curved obstacle at the contact law's offset is not held to the
    tangent planes it passed. The plane is that of the closest points at s, m toward the
    cloth, h = max_b m . xo1_b + delta (delta = min(T, max(D0, FLOOR T)) for a
    point-triangle row, FLOOR T for the others), with the obstacle's velocity u there."""
    ti.loop_config(serialize=ti.static(serial_count(rows.capacity)))
    for c in range(count):
        ids, kind = rows.ids[c], rows.kind[c]
        g, alpha = _gap(ids, kind, x0, x1, o.xo0, o.xo1, 0.0)
        d0 = g.norm()
        # the plane is taken where the gap comes down to FLOOR T; a point-triangle row's
        # holds the cloth at the contact law's offset T, or at its start's gap where it
        # began nearer (no push away), at least FLOOR T; the others' at FLOOR T
        target = FLOOR * thickness
        delta = target
        if kind == POINT_TRIANGLE:
            delta = ti.min(thickness, ti.max(d0, target))
        closing = _closing(ids, kind, x0, x1, o.xo0, o.xo1)
        reach = target * (1.0 + ADVANCE_SLACK)      # a gap this near has come down to it
        s, d, hit = 0.0, d0, d0 <= reach
        if d0 - closing > reach:
            s = 1.0                 # it cannot close to the target within the step
        elif not hit:
            # nor where the gap at either end, closing at most ``closing`` over the
            # step, keeps it above the target all along: d(s) >= max(d0 - closing s,
            # d1 - closing (1 - s)) >= (d0 + d1 - closing) / 2
            g1, _d1 = _gap(ids, kind, x0, x1, o.xo0, o.xo1, 1.0)
            if d0 + g1.norm() - closing > 2.0 * reach:
                s = 1.0
        for _ in range(ADVANCES):
            if hit or s >= 1.0 or closing <= 0.0:
                break
            s = ti.min(s + (d - target) / closing, 1.0)
            g, alpha = _gap(ids, kind, x0, x1, o.xo0, o.xo1, s)
            d = g.norm()
            hit = d <= reach
        if s < 1.0 and not hit:
            hit = True              # out of advances short of the end: take the plane here
        m = g / ti.max(d, LEAST_GAP)
        if kind == POINT_TRIANGLE:
            m = _patch_normal(o, ids, rows.face[c], alpha, s, g, m)
        level, weight = -1e30, 0.0
        u = ti.Vector.zero(float, 3)
        for k in ti.static(range(4)):
            if not is_cloth(kind, k):
                level = ti.max(level, m.dot(o.xo1[ids[k]]))
                u += abs(alpha[k]) * (o.xo1[ids[k]] - o.xo0[ids[k]]) / dt
                weight += abs(alpha[k])
        rows.m[c] = m
        rows.u[c] = u / ti.max(weight, 1e-30)
        rows.delta[c] = delta
        rows.h[c] = level + delta if hit and d > LEAST_GAP else INACTIVE


@ti.func
def _patch_normal(o: ti.template(), ids, face, alpha, s, g, m):
    """A point-triangle row's normal: the triangle's own, toward the point, where the
    point's closest point on it (weights -alpha[1:]) lies on an edge or corner inside a
    flat patch (``_flat``); else m, the gap's direction. Beside a triangle of a flat
    surface the gap's direction tilts toward the surface (a point T/4 above the top of a
    turntable's platter, 1 cm across from a triangle's edge: 78 degrees from the normal)
    and its plane pushed the cloth sideways by up to 1.3 cm; the surface's normal
    separates it from that triangle too (the point is not below the patch's plane)."""
    zeros, at = 0, 0
    for k in ti.static(range(3)):
        if alpha[k + 1] == 0.0:
            zeros += 1
        else:
            at = k
    flat = o.flat[face]
    inside = False
    if zeros == 1:
        for k in ti.static(range(3)):
            if alpha[k + 1] == 0.0:
                inside = (flat >> ((k + 1) % 3)) & 1 == 1     # the edge across corner k
    elif zeros == 2:
        inside = (flat >> (3 + at)) & 1 == 1
    out = m
    if inside:
        y = [o.xo0[ids[k]] + s * (o.xo1[ids[k]] - o.xo0[ids[k]]) for k in ti.static(range(1, 4))]
        n = (y[1] - y[0]).cross(y[2] - y[0])
        if n.norm() > 0.0:
            n = n.normalized()
            out = n if n.dot(g) >= 0.0 else -n
    return out


@ti.kernel
def _project(o: ti.template(), rows: ti.template(), count: ti.i32, x0: ti.template(),
             x1: ti.template(), v1: ti.template(), stop_normal: ti.template(), dt: float,
             sweeps: ti.i32) -> ti.types.vector(2, ti.i32):
    """``ObstaclePairs.project``: a vertex short of a half-space moves onto it along its
    normal (it slides along the plane of the contact its path made)."""
    total, ran = 0, 0
    ti.loop_config(serialize=True)
    for _ in range(sweeps):
        corrected = 0
        for c in range(count):
            ids, kind = rows.ids[c], rows.kind[c]
            m, h = rows.m[c], rows.h[c]
            for k in ti.static(range(4)):
                if is_cloth(kind, k):
                    a = ids[k]
                    short = h - m.dot(x1[a])
                    if o.inv_mass[a] > 0.0 and short > SLACK * rows.delta[c]:
                        x1[a] += short * m
                        vn = (v1[a] - rows.u[c]).dot(m)
                        if vn < 0.0:
                            v1[a] -= vn * m
                        stop_normal[a] = m
                        corrected += 1
        total += corrected
        ran += 1
        if corrected == 0:
            break
    return ti.Vector([total, ran])


@ti.func
def _short(o: ti.template(), rows: ti.template(), c, x1):
    """Whether a free cloth vertex of row c is below its half-space at x1."""
    ids, kind = rows.ids[c], rows.kind[c]
    bad = False
    for k in ti.static(range(4)):
        if is_cloth(kind, k):
            a = ids[k]
            if o.inv_mass[a] > 0.0 and rows.h[c] - rows.m[c].dot(x1[a]) > SLACK * rows.delta[c]:
                bad = True
    return bad


@ti.kernel
def _violations(o: ti.template(), rows: ti.template(), count: ti.i32, x1: ti.template()) -> ti.i32:
    bad = 0
    ti.loop_config(serialize=ti.static(serial_count(rows.capacity)))
    for c in range(count):
        if _short(o, rows, c, x1):
            bad += 1
    return bad


@ti.kernel
def _carry(o: ti.template(), rows: ti.template(), count: ti.i32, x0: ti.template(), x1: ti.template(),
           v1: ti.template(), t0: float, dt: float) -> ti.i32:
    """Carry the free cloth vertices of each violated row with the obstacle (``carry``);
    a carried vertex's row is kept (h = INACTIVE: it moves as the obstacle does)."""
    moved = 0
    ti.loop_config(serialize=True)
    for c in range(count):
        if _short(o, rows, c, x1):
            ids, kind = rows.ids[c], rows.kind[c]
            b = ids[1] if kind == POINT_TRIANGLE else (ids[2] if kind == EDGE_EDGE else ids[0])
            col = o.table.data[o.row_of[b]]
            deforming = o.store.meshes[col.mesh][6]
            r0, c0 = pose(col, t0)
            r1, c1 = pose(col, t0 + dt)
            for k in ti.static(range(4)):
                if is_cloth(kind, k):
                    a = ids[k]
                    if o.inv_mass[a] > 0.0:
                        end = r1 @ (r0.transpose() @ (x0[a] - c0)) + c1
                        if deforming:
                            end = x0[a] + rows.u[c] * dt
                        v1[a] = (end - x0[a]) / dt
                        x1[a] = end
                        moved += 1
            rows.h[c] = INACTIVE
    return moved
