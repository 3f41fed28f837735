"""Triangle-mesh colliders in Taichi: ``MeshStore`` holds every mesh collider of a scene
(vertices, triangles in the order of their hierarchy's leaves, pseudo normals, the
hierarchy's boxes: ``trimesh.py``) and answers, for a collider row ``col`` of the
collider table (its ``mesh`` the store's mesh index):

  - ``contact(col, x, t)``: (phi, outward unit normal n, surface velocity u) of x at time
    t: phi is the distance to the mesh's closest point, signed by the pseudo normal of
    the feature that point lies on where the mesh is closed (negative inside), unsigned
    on an open mesh (two-sided: n points from the mesh to x). Only points within a reach
    (at most the collider's, ``col.extent[0]``) are searched; farther ones get phi =
    reach.
  - ``ray_hit(col, o, d, t)`` and ``normal(col, p, t)``: the renderer's ray hit and the
    shading normal (the vertex normals interpolated at the closest point).

A rigid mesh is stored in its own frame, where its hierarchy was built once: at time t
it is turned by R(t) = exp(t [spin]) R0 and moved to c(t) = c0 + t v (``col.rotation``,
``col.center``, ``col.spin``, ``col.velocity``), and a query is made in that frame. A
deforming one is stored in the world at the two ends ta, tb of the current step
(``set_frames``), its vertices moving on straight lines between them; its hierarchy's
boxes hold both ends.
"""
import numpy as np
import taichi as ti

from .. import runtime
from . import raycast, trimesh
from .proximity import triangle_weights

STACK = 64        # the traversal's stack (a tree of 2^32 leaves needs 33)
TINY = 1e-12      # m: below this a distance has no direction of its own
QUERY_WORK = 64   # a query of the hierarchy costs about this many simple loop items
                  # (``runtime.serial``: a loop of a few thousand queries runs threaded)
DEPTH_START = 1e-3   # ``depth``'s rays start this fraction of their length below a face
GRAZING = 1e-3    # an edge this near its plane (|cos| to the normal) lies in a triangle's
                  # plane: it touches it, and float32's rounding would make a hit of it


@ti.func
def spin_matrix(w, t):
    """exp(t [w]): the rotation by |w| t about w (Rodrigues)."""
    angle = w.norm() * t
    r = ti.Matrix.identity(float, 3)
    if abs(angle) > 0.0:
        k = w / w.norm()
        kx = ti.Matrix([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        r += ti.sin(angle) * kx + (1.0 - ti.cos(angle)) * (kx @ kx)
    return r


@ti.func
def pose(col, t):
    """(R(t), c(t)) of a rigid collider row (module docstring)."""
    return spin_matrix(col.spin, t) @ col.rotation, col.center + t * col.velocity


@ti.func
def _box_distance2(lo, hi, q):
    d = ti.max(lo - q, q - hi, 0.0)
    return d.dot(d)


@ti.func
def _slab(lo, hi, o, d, best):
    """Whether the ray o + s d meets the box for some 0 <= s < best."""
    t_near, t_far = 0.0, best
    for k in ti.static(range(3)):
        inv = 1.0 / d[k] if abs(d[k]) > 1e-12 else 1e30
        t0, t1 = (lo[k] - o[k]) * inv, (hi[k] - o[k]) * inv
        t_near = ti.max(t_near, ti.min(t0, t1))
        t_far = ti.min(t_far, ti.max(t0, t1))
    return t_near <= t_far


@ti.data_oriented
class MeshStore:
    """Every mesh collider of a scene (module docstring).

    Attributes:
        meshes: per mesh (tri_first, tri_count, vert_first, node_first, leaves, closed,
            deforming), i32; times: per mesh (ta, tb), the deforming ones' frames.
        va, vb: vertex positions (own frame; the two frames of a deforming one);
        tris: global vertex ids, each mesh's in its hierarchy's leaf order;
        face_n, edge_n (3 x 3, row k: edge k -> k+1), vertex_n: pseudo normals (own frame);
        node_lo, node_hi: the hierarchies' boxes (``trimesh.bvh``).
    """

    def __init__(self, colliders):
        real = runtime.real()
        self.records = []
        vert_first = tri_first = node_first = 0
        for c in colliders:
            v, tris = np.asarray(c["vertices"], dtype=np.float64), np.asarray(c["faces"])
            lo, hi = _boxes(v, tris)
            order, node_lo, node_hi, leaves = trimesh.bvh(lo, hi)
            self.records.append({"tris": tris[order], "order": order, "leaves": leaves,
                                 "edges": trimesh.edge_index(tris[order]),
                                 "v": v, "vert_first": vert_first, "tri_first": tri_first,
                                 "node_first": node_first, "node_lo": node_lo,
                                 "node_hi": node_hi, "closed": bool(c["closed"]),
                                 "deforming": c.get("deform") is not None})
            vert_first += len(v)
            tri_first += len(tris)
            node_first += 2 * leaves
        count = max(len(self.records), 1)
        self.meshes = ti.Vector.field(7, ti.i32, shape=count)
        self.times = ti.Vector.field(2, real, shape=count)
        self.va = ti.Vector.field(3, real, shape=max(vert_first, 1))
        self.vb = ti.Vector.field(3, real, shape=max(vert_first, 1))
        self.vertex_n = ti.Vector.field(3, real, shape=max(vert_first, 1))
        self.tris = ti.Vector.field(3, ti.i32, shape=max(tri_first, 1))
        self.face_n = ti.Vector.field(3, real, shape=max(tri_first, 1))
        self.edge_n = ti.Matrix.field(3, 3, real, shape=max(tri_first, 1))
        self.node_lo = ti.Vector.field(3, real, shape=max(node_first, 1))
        self.node_hi = ti.Vector.field(3, real, shape=max(node_first, 1))
        self._upload_all()

    def _upload_all(self):
        npr = runtime.numpy_real()
        table = np.zeros((self.meshes.shape[0], 7), np.int32)
        parts = {name: [] for name in ("v", "tris", "face_n", "edge_n", "vertex_n", "lo", "hi")}
        for m, r in enumerate(self.records):
            table[m] = (r["tri_first"], len(r["tris"]), r["vert_first"], r["node_first"],
                        r["leaves"], r["closed"], r["deforming"])
            face, edge, vertex = trimesh.pseudo_normals(r["v"], r["tris"], r["edges"])
            parts["v"].append(r["v"])
            parts["tris"].append(r["tris"] + r["vert_first"])
            parts["face_n"].append(face)
            parts["edge_n"].append(edge)
            parts["vertex_n"].append(vertex)
            parts["lo"].append(r["node_lo"])
            parts["hi"].append(r["node_hi"])
        self.meshes.from_numpy(table)
        if not self.records:
            return
        cat = {k: np.concatenate(p) for k, p in parts.items()}
        for field, key in ((self.va, "v"), (self.vb, "v"), (self.vertex_n, "vertex_n"),
                           (self.face_n, "face_n"), (self.edge_n, "edge_n"),
                           (self.node_lo, "lo"), (self.node_hi, "hi")):
            field.from_numpy(_finite(cat[key]).astype(npr))
        self.tris.from_numpy(cat["tris"].astype(np.int32))

    def open(self, m):
        """Take mesh m as open (two-sided; its distance unsigned)."""
        self.records[m]["closed"] = False
        row = self.meshes[m]
        row[5] = 0
        self.meshes[m] = row

    def set_frames(self, m, ta, tb, va, vb):
        """A deforming mesh m's vertices (own frame) at the ends ta < tb of a step: its
        hierarchy refit over both, its pseudo normals those at tb."""
        r = self.records[m]
        npr = runtime.numpy_real()
        first = r["vert_first"]
        a_lo, a_hi = _boxes(va, r["tris"])
        b_lo, b_hi = _boxes(vb, r["tris"])
        lo, hi = np.minimum(a_lo, b_lo), np.maximum(a_hi, b_hi)
        node_lo, node_hi = trimesh.refit(np.arange(len(lo)), lo, hi, r["leaves"])
        face, edge, vertex = trimesh.pseudo_normals(vb, r["tris"], r["edges"])
        _write(self.va, first, va.astype(npr))
        _write(self.vb, first, vb.astype(npr))
        _write(self.vertex_n, first, vertex.astype(npr))
        _write(self.face_n, r["tri_first"], face.astype(npr))
        _write(self.edge_n, r["tri_first"], edge.astype(npr))
        _write(self.node_lo, r["node_first"], _finite(node_lo).astype(npr))
        _write(self.node_hi, r["node_first"], _finite(node_hi).astype(npr))
        self.times[m] = (ta, tb)

    # -- in the mesh's frame -------------------------------------------------------------
    @ti.func
    def _share(self, m, t):
        """How far along from va to vb a deforming mesh m is at t (0 for a rigid one)."""
        s = 0.0
        if self.meshes[m][6]:
            ta, tb = self.times[m][0], self.times[m][1]
            if tb > ta:
                s = ti.math.clamp((t - ta) / (tb - ta), 0.0, 1.0)
        return s

    @ti.func
    def _vertex(self, i, s):
        return self.va[i] + s * (self.vb[i] - self.va[i])

    @ti.func
    def _frame(self, col, t):
        """(R, c) taking the mesh's frame to the world at t (identity for a deforming mesh)."""
        r, c = pose(col, t)
        if self.meshes[col.mesh][6]:
            r, c = ti.Matrix.identity(float, 3), ti.Vector.zero(float, 3)
        return r, c

    @ti.func
    def closest(self, m, q, s, reach):
        """(triangle, barycentric weights, squared distance) of the point of mesh m (at
        share s of a deforming one's step) closest to q, searched within ``reach``;
        triangle -1 where none is."""
        info = self.meshes[m]
        leaves, node0, tri0, tris = info[4], info[3], info[0], info[1]
        best, best_tri = reach * reach, -1
        best_w = ti.Vector([1.0, 0.0, 0.0])
        stack = ti.Vector([0] * STACK)
        stack[0], top = 1, 1
        while top > 0:
            top -= 1
            k = stack[top]
            if _box_distance2(self.node_lo[node0 + k], self.node_hi[node0 + k], q) < best:
                if k >= leaves:
                    for j in range(trimesh.LEAF):
                        tri = (k - leaves) * trimesh.LEAF + j
                        if tri < tris:
                            i = self.tris[tri0 + tri]
                            a, b, c = (self._vertex(i[0], s), self._vertex(i[1], s),
                                       self._vertex(i[2], s))
                            w = triangle_weights(q, a, b, c)
                            g = q - (w[0] * a + w[1] * b + w[2] * c)
                            if g.dot(g) < best:
                                best, best_tri, best_w = g.dot(g), tri0 + tri, w
                else:
                    near, far = 2 * k, 2 * k + 1
                    if (_box_distance2(self.node_lo[node0 + far], self.node_hi[node0 + far], q)
                            < _box_distance2(self.node_lo[node0 + near],
                                             self.node_hi[node0 + near], q)):
                        near, far = far, near
                    stack[top], stack[top + 1] = far, near
                    top += 2
        return best_tri, best_w, best

    @ti.func
    def _pseudo_normal(self, tri, w):
        """The pseudo normal of the feature of triangle ``tri`` that weights w lie on."""
        zeros = 0
        for k in ti.static(range(3)):
            if w[k] <= 0.0:
                zeros += 1
        pn = self.face_n[tri]
        if zeros == 2:
            for k in ti.static(range(3)):
                if w[k] > 0.0:
                    pn = self.vertex_n[self.tris[tri][k]]
        elif zeros == 1:
            for k in ti.static(range(3)):
                if w[k] <= 0.0:     # the edge opposite corner k runs from k + 1 to k + 2
                    row = (k + 1) % 3
                    pn = ti.Vector([self.edge_n[tri][row, 0], self.edge_n[tri][row, 1],
                                    self.edge_n[tri][row, 2]])
        return pn

    @ti.func
    def signed(self, m, q, s, reach):
        """(phi, unit normal from the mesh toward q, closest point, triangle, weights) of
        q in mesh m's frame (at share s of a deforming one's step), searched within
        ``reach``: phi the distance to the closest point, negative inside a closed mesh
        (the pseudo normal's side); triangle -1 and phi = reach where nothing is nearer."""
        tri, w, dist2 = self.closest(m, q, s, reach)
        phi, nl, point = reach, ti.Vector([0.0, 1.0, 0.0]), q
        if tri >= 0:
            i = self.tris[tri]
            point = (w[0] * self._vertex(i[0], s) + w[1] * self._vertex(i[1], s)
                     + w[2] * self._vertex(i[2], s))
            d = ti.sqrt(dist2)
            pn = self._pseudo_normal(tri, w)
            nl = self.face_n[tri]
            if d > TINY:
                nl = (q - point) / d
            phi = d
            if self.meshes[m][5] and (q - point).dot(pn) < 0.0:
                phi, nl = -d, -nl
            elif d <= TINY and self.meshes[m][5]:
                nl = pn.normalized()
        return phi, nl, point, tri, w

    @ti.func
    def contact(self, col, x, t, reach):
        """(phi, outward unit normal, surface velocity) of x at time t (module docstring),
        searched within ``reach`` (phi = reach beyond it)."""
        m = col.mesh
        r, c = self._frame(col, t)
        s = self._share(m, t)
        phi, nl, point, tri, w = self.signed(m, r.transpose() @ (x - c), s, reach)
        n, u = ti.Vector([0.0, 1.0, 0.0]), col.velocity
        if tri >= 0:
            i = self.tris[tri]
            n = r @ nl
            u = col.velocity + col.spin.cross(r @ point)
            if self.meshes[m][6]:
                u = ti.Vector.zero(float, 3)
                span = self.times[m][1] - self.times[m][0]
                if span > 0.0:
                    for k in ti.static(range(3)):
                        u += w[k] * (self.vb[i[k]] - self.va[i[k]]) / span
        return phi, n, u

    # -- the renderer ----------------------------------------------------------------------
    @ti.func
    def ray_hit(self, col, o, d, t):
        """The nearest s > 0 where the ray o + s d (d unit) meets the mesh, or -1."""
        m = col.mesh
        r, c = self._frame(col, t)
        ol = r.transpose() @ (ti.cast(o, float) - c)
        dl = r.transpose() @ ti.cast(d, float)
        best = self.first_hit(m, ol, dl, self._share(m, t), 1e30, -1, -1, 0.0, False)
        return best if best < 1e30 else -1.0

    @ti.func
    def first_hit(self, m, o, d, s, limit, skip_a, skip_b, grazing, entering: ti.template()):
        """The nearest 0 < hit < limit along the ray o + hit d in mesh m's frame (at share
        s of a deforming one's step) on a triangle with neither vertex skip_a nor skip_b
        that the ray does not graze (|d . n| > ``grazing``, n its unit normal) and, with
        ``entering``, that it enters (d . n < 0: a closed mesh's faces face out); ``limit``
        where none is."""
        info = self.meshes[m]
        leaves, node0, tri0, tris = info[4], info[3], info[0], info[1]
        best = limit
        stack = ti.Vector([0] * STACK)
        stack[0], top = 1, 1
        while top > 0:
            top -= 1
            k = stack[top]
            if _slab(self.node_lo[node0 + k], self.node_hi[node0 + k], o, d, best):
                if k >= leaves:
                    for j in range(trimesh.LEAF):
                        tri = (k - leaves) * trimesh.LEAF + j
                        if tri < tris:
                            i = self.tris[tri0 + tri]
                            cos = d.dot(self.face_n[tri0 + tri].normalized())
                            if ((i != skip_a).all() and (i != skip_b).all()
                                    and abs(cos) > grazing and (not entering or cos < 0.0)):
                                h = raycast.hit_triangle(o, d, self._vertex(i[0], s),
                                                         self._vertex(i[1], s),
                                                         self._vertex(i[2], s))
                                if 0.0 < h[0] < best:
                                    best = h[0]
                else:
                    stack[top], stack[top + 1] = 2 * k + 1, 2 * k
                    top += 2
        return best

    @ti.func
    def world_vertex(self, col, i, t):
        """(position, unit vertex normal) in the world at time t of vertex i (a store
        index) of collider row col's mesh: the triangles ``ray_hit`` meets and the
        normals ``normal`` interpolates."""
        r, c = self._frame(col, t)
        return r @ self._vertex(i, self._share(col.mesh, t)) + c, r @ self.vertex_n[i].normalized()

    def crossed(self, m):
        """Whether mesh m crosses itself: one of its edges passes through one of its
        triangles that shares no vertex with it (each edge cast as a segment from its
        first vertex; one in the triangle's plane touches it: ``GRAZING``)."""
        return int(_crossed(self, m, self.records[m]["tri_first"],
                            len(self.records[m]["tris"]))) > 0

    def depth(self, m, limit):
        """The least depth of closed mesh m under its faces (m): from each face's centre,
        how far a ray into the solid (against the face's normal) runs before it meets
        the mesh again, ``limit`` where it runs farther; the thickness of its thinnest
        plate, rod or wall."""
        r = self.records[m]
        return float(_depth(self, m, r["tri_first"], len(r["tris"]), limit))

    @ti.func
    def normal(self, col, p, t):
        """The shading normal (float32) at surface point p: the vertex normals of the
        closest triangle interpolated there."""
        m = col.mesh
        r, c = self._frame(col, t)
        q = r.transpose() @ (ti.cast(p, float) - c)
        s = self._share(m, t)
        tri, w, _ = self.closest(m, q, s, 1e30)
        n = ti.Vector([0.0, 1.0, 0.0])
        if tri >= 0:
            i = self.tris[tri]
            n = (w[0] * self.vertex_n[i[0]].normalized() + w[1] * self.vertex_n[i[1]].normalized()
                 + w[2] * self.vertex_n[i[2]].normalized())
            n = r @ n.normalized()
        return ti.cast(n, ti.f32)


@ti.kernel
def _crossed(store: ti.template(), m: ti.i32, first: ti.i32, count: ti.i32) -> ti.i32:
    crossings = 0
    for f in range(first, first + count):
        i = store.tris[f]
        for k in ti.static(range(3)):
            a, b = i[k], i[(k + 1) % 3]
            along = store.va[b] - store.va[a]
            length = along.norm()
            if length > 0.0:
                hit = store.first_hit(m, store.va[a], along / length, 0.0, length, a, b,
                                      GRAZING, False)
                if hit < length:
                    crossings += 1
    return crossings


@ti.kernel
def _depth(store: ti.template(), m: ti.i32, first: ti.i32, count: ti.i32,
           limit: float) -> float:
    least = limit
    below = DEPTH_START * limit
    for f in range(first, first + count):
        i = store.tris[f]
        n = store.face_n[f].normalized()
        # from just below the face (its own plane then lies behind the ray)
        start = (store.va[i[0]] + store.va[i[1]] + store.va[i[2]]) / 3.0 - below * n
        ti.atomic_min(least, below + store.first_hit(m, start, -n, 0.0, limit - below, -1,
                                                     -1, 0.0, False))
    return least


def _boxes(v, tris):
    """(lo, hi) (F, 3) of triangles ``tris`` of vertices v."""
    corners = np.asarray(v)[np.asarray(tris)]
    return corners.min(axis=1), corners.max(axis=1)


def _finite(a):
    """Empty boxes' infinities as large finite numbers (fields hold no inf in float32)."""
    return np.clip(a, -1e30, 1e30)


@ti.kernel
def _write(field: ti.template(), first: ti.i32, values: ti.types.ndarray()):
    """field[first:first + len(values)] = values, those rows only (a deforming mesh's, each
    step: a whole field read and written back cost its step more than its normals)."""
    for i in range(values.shape[0]):
        if ti.static(field.m > 1):
            for a, b in ti.static(ti.ndrange(field.n, field.m)):
                field[first + i][a, b] = values[i, a, b]
        else:
            for a in ti.static(range(field.n)):
                field[first + i][a] = values[i, a]
