"""The contact topology of a scene's cloths and ropes, for self-collision.

``contact_topology(scene)`` (NumPy) lists what can touch: the particles of every cloth and
rope, the cloth triangles, the edges (triangle edges and rope segments, each once), and
each particle's mesh neighbours (the particles an edge joins it to). ``SelfCollisionTable``
holds them as Taichi fields with the contact settings, in the Model.

The rule for pairs that touch by construction: a particle and a triangle, or two edges,
never repel when they share a particle or when a particle of one is a mesh neighbour of a
particle of the other (``SelfCollisionTable.excluded``).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..graph import csr_layout

# the order of SelfCollisionTable.params
# how far (a sine) a contact's direction may lie outside its feature's normal cone and count:
# on a flat layer an edge's cone is a plane, which rounding puts a direction on either side of
CONE_TOLERANCE = 1e-3

PARAMS = ("thickness", "stiffness", "friction", "damping", "stick_velocity", "skin")


def contact_topology(scene):
    """dict of int arrays: points (P,), triangles (T,3), edges (E,2) with edges[:, 0] <
    edges[:, 1], and the neighbour lists as CSR: neighbours[start[i]:start[i + 1]] are
    particle i's mesh neighbours (start has num_particles + 1 entries)."""
    triangles = scene.triangles
    pieces = [triangles[:, [a, b]] for a, b in ((0, 1), (1, 2), (2, 0))]
    pieces += [np.stack([r.particles[:-1], r.particles[1:]], 1) for r in scene.ropes]
    edges = np.sort(np.concatenate(pieces), axis=1) if pieces else np.zeros((0, 2), np.int64)
    edges = np.unique(edges, axis=0)
    points = np.unique(np.concatenate([c.particles.ravel() for c in scene.cloths]
                                      + [r.particles for r in scene.ropes]))
    both = np.concatenate([edges, edges[:, ::-1]])
    start, order = csr_layout(both[:, 0], scene.num_particles, then=both[:, 1])
    both = both[order]
    return {"points": points, "triangles": triangles, "edges": edges,
            "start": start, "neighbours": both[:, 1],
            "across": _across(triangles, both, scene.num_particles)}


def _across(triangles, directed, n):
    """(len(directed), 2): the vertices opposite directed edge (i, j) in the (at most two)
    triangles that hold it, -1 where it has fewer."""
    out = np.full((len(directed), 2), -1, dtype=np.int64)
    if not len(triangles):
        return out
    sides = np.concatenate([triangles[:, list(c)] for c in ((0, 1, 2), (1, 2, 0), (2, 0, 1))])
    key = np.sort(sides[:, :2], axis=1) @ np.array([n, 1])
    order = np.argsort(key, kind="stable")
    key, opposite = key[order], sides[order, 2]
    wanted = np.sort(directed, axis=1) @ np.array([n, 1])
    first = np.searchsorted(key, wanted)
    for slot in range(2):
        at = np.minimum(first + slot, len(key) - 1)
        hit = key[at] == wanted
        out[hit, slot] = opposite[at[hit]]
    return out


def cloth_primitives(scene):
    """{"edges": (E, 2), "triangles": (T, 3)} of the scene's cloths and ropes (empty
    where it has none): what a mesh collider's pairs take (``obstacle.py``)."""
    if not scene.cloths and not scene.ropes:
        return {"edges": np.zeros((0, 2), np.int64), "triangles": np.zeros((0, 3), np.int64)}
    topo = contact_topology(scene)
    return {"edges": topo["edges"], "triangles": topo["triangles"]}


def resolve(scene):
    """The scene's self-collision settings with stiffness None replaced by the mean
    stiffness of its structural springs."""
    settings = dict(scene.self_collision)
    if settings["stiffness"] is None:
        structural = scene.mean_stiffness("structural")
        if structural is None or structural <= 0.0:
            raise SceneError("set_self_collision(stiffness=None) takes the mean structural "
                             "spring stiffness, and the scene has no structural springs: "
                             "give stiffness= (N/m)")
        settings["stiffness"] = structural
    return settings


@ti.data_oriented
class SelfCollisionTable:
    """The static part of self-collision as Taichi fields.

    Attributes:
        points: (P,) particle ids; triangles: (T,) of 3 x i32; edges: (E,) of 2 x i32;
        start, neighbours: the mesh neighbour lists (CSR, i32);
        params: (6,) reals in ``PARAMS`` order; settings: the same as a dict;
        point_count, triangle_count, edge_count: sizes.
    """

    def __init__(self, scene):
        if not scene.cloths and not scene.ropes:
            raise SceneError("set_self_collision needs a cloth or a rope in the scene "
                             "(it has none)")
        self.settings = resolve(scene)
        topo = contact_topology(scene)
        self.point_count = len(topo["points"])
        self.triangle_count = len(topo["triangles"])
        self.edge_count = len(topo["edges"])
        self.points = _upload(ti.i32, topo["points"], ())
        self.triangles = _upload(ti.i32, topo["triangles"], (3,))
        self.edges = _upload(ti.i32, topo["edges"], (2,))
        self.start = _upload(ti.i32, topo["start"], ())
        self.neighbours = _upload(ti.i32, topo["neighbours"], ())
        self.across = _upload(ti.i32, topo["across"], (2,))
        self.params = _upload(runtime.real(), np.array([self.settings[k] for k in PARAMS]), ())

    @ti.func
    def adjacent(self, i, j):
        """i == j, or j is one of i's mesh neighbours."""
        return i == j or self._slot(i, j) >= 0

    @ti.func
    def excluded(self, ids, n_a):
        """Whether the contact between particles ids[:n_a] (one side) and ids[n_a:] (the
        other; ids has 4 entries) touches by construction: a shared particle, or mesh
        neighbours across the sides."""
        out = False
        for a in range(n_a):
            for b in range(n_a, 4):
                if self.adjacent(ids[a], ids[b]):
                    out = True
        return out

    @ti.func
    def _slot(self, i, j):
        """The index of j in i's neighbour list (-1 where they are not neighbours)."""
        out = -1
        for k in range(self.start[i], self.start[i + 1]):
            if self.neighbours[k] == j:
                out = k
        return out

    @ti.func
    def _beyond(self, x, i, j, q, t):
        """Whether direction t from q on edge (i, j) leaves each triangle at the edge across
        it (t lies in the edge's normal cone), and whether the edge has a triangle."""
        inside, k = False, self._slot(i, j)
        across = self.across[ti.max(k, 0)]
        for s in ti.static(range(2)):
            if k >= 0 and across[s] >= 0:
                if t.dot(_outward(x, i, j, across[s], q)) < -CONE_TOLERANCE:
                    inside = True
        return not inside, k >= 0 and across[0] >= 0

    @ti.func
    def counts(self, ids, kind, alpha, g, x):
        """Whether a contact (gap g = sum_k alpha_k x_k, not zero) is the one that counts
        for its closest points: a point over a triangle's edge or corner is in contact with
        the mesh there once, through the feature whose normal cone holds the direction
        (Offset Geometric Contact's rule), not once per triangle or edge next to it."""
        t = g / ti.max(g.norm(), 1e-30)
        out = True
        if kind == 0:
            out = self._point_feature(ids, alpha, t, x)
        else:
            s, u = alpha[1], -alpha[3]
            q_a = x[ids[0]] * alpha[0] + x[ids[1]] * s
            q_b = -(x[ids[2]] * alpha[2] + x[ids[3]] * alpha[3])
            beyond_a, cloth_a = self._beyond(x, ids[0], ids[1], q_a, -t)
            beyond_b, cloth_b = self._beyond(x, ids[2], ids[3], q_b, t)
            end_a = s <= 0.0 or s >= 1.0
            end_b = u <= 0.0 or u >= 1.0
            if (end_a and cloth_b) or (end_b and cloth_a):
                out = False         # a point against a cloth's edge or corner: a row of its own
            elif not end_a and not end_b:
                out = beyond_a and beyond_b
        return out

    @ti.func
    def _corner_counts(self, p, v, b, c, t, x):
        """Whether point p's contact with corner v through triangle (v, b, c), b < c, counts:
        t lies in v's normal cone (no edge at v leads toward p), and of v's triangles that
        do not touch p by construction, (v, b, c) has the smallest (b, c)."""
        out = True
        for k in range(self.start[v], self.start[v + 1]):
            u = self.neighbours[k]
            to = x[u] - x[v]
            if t.dot(to) > CONE_TOLERANCE * to.norm():
                out = False
            for s in ti.static(range(2)):
                o = self.across[k][s]
                lo, hi = ti.min(u, o), ti.max(u, o)
                if o >= 0 and (lo < b or (lo == b and hi < c)):
                    if not self.excluded(ti.Vector([p, v, u, o]), 1):
                        out = False
        return out

    @ti.func
    def _point_feature(self, ids, alpha, t, x):
        """``counts`` for a point against a triangle, by the triangle's closest feature."""
        p = ids[0]
        on = 0
        for k in ti.static(range(1, 4)):
            if alpha[k] < 0.0:
                on += 1
        out = True
        if on == 2:         # an edge: over the other triangle there, or counted by it
            o, i, j = ids[1], ids[2], ids[3]
            if alpha[2] == 0.0:
                o, i, j = ids[2], ids[3], ids[1]
            elif alpha[3] == 0.0:
                o, i, j = ids[3], ids[1], ids[2]
            k = self._slot(i, j)
            q = -(alpha[1] * x[ids[1]] + alpha[2] * x[ids[2]] + alpha[3] * x[ids[3]])
            across = self.across[ti.max(k, 0)]
            for s in ti.static(range(2)):
                other = across[s]
                if k >= 0 and other >= 0 and other != o:
                    if not self.excluded(ti.Vector([p, i, j, other]), 1):
                        if t.dot(_outward(x, i, j, other, q)) < -CONE_TOLERANCE or other < o:
                            out = False
        elif on == 1:       # a corner: in its normal cone, counted by one triangle there
            v, b, c = ids[1], ids[2], ids[3]
            if alpha[2] < 0.0:
                v, b, c = ids[2], ids[3], ids[1]
            elif alpha[3] < 0.0:
                v, b, c = ids[3], ids[1], ids[2]
            out = self._corner_counts(p, v, ti.min(b, c), ti.max(b, c), t, x)
        return out


@ti.func
def _outward(x, i, j, o, q):
    """The unit direction from triangle (i, j, o) out across its edge (i, j), at q on it."""
    e = (x[j] - x[i]).normalized()
    m = q - x[o]
    m -= m.dot(e) * e
    return m / ti.max(m.norm(), 1e-30)


def _upload(dtype, values, inner):
    values = np.asarray(values)
    rows = max(len(values), 1)
    field = ti.field(dtype, shape=rows) if not inner else ti.Vector.field(inner[0], dtype,
                                                                           shape=rows)
    if len(values):
        field.from_numpy(values.astype(runtime.numpy_real() if dtype != ti.i32 else np.int32))
    return field
