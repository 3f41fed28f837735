"""The contact topology of a scene's cloths and ropes, for self-collision.

``contact_topology(scene)`` (NumPy) lists what can touch: the particles of every cloth and
rope, the cloth triangles, the edges (triangle edges and rope segments, each once), and
each particle's mesh neighbours (the particles an edge joins it to). ``SelfCollisionTable``
holds them as Taichi fields with the contact settings, in the Model.

The rule for pairs that touch by construction: a particle and a triangle, or two edges,
never repel when they share a particle or when a particle of one is a mesh neighbour of a
particle of the other (``SelfCollisionTable.excluded``). A seam's two particles (a spring
of kind "seam", ``Scene.sew``) count as one: each is a neighbour of the other and of the
other's neighbours, as they would be had the cloths been one mesh, so the seam's pull
closes it to zero distance instead of stopping at the contact thickness. For the same
reason a seam's particles are one in the test for a shared particle (``twin``): a
particle and a triangle of its seam partner are no candidate pair at all, so that the
guard, which keeps even the pairs that do not repel from crossing and a fraction of the
thickness apart, leaves a closing seam alone.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..geometry.graph import csr_layout
from ..scene.scene import KIND_CODE

# the order of SelfCollisionTable.params
PARAMS = ("thickness", "stiffness", "friction", "damping", "stick_velocity", "skin")


def contact_topology(scene):
    """dict of int arrays: points (P,), triangles (T,3), edges (E,2) with edges[:, 0] <
    edges[:, 1], and the neighbour lists as CSR: neighbours[start[i]:start[i + 1]] are
    particle i's mesh neighbours (start has num_particles + 1 entries), and twin (N,): each
    particle's seam group (``_twins``)."""
    triangles = scene.triangles
    pieces = [triangles[:, [a, b]] for a, b in ((0, 1), (1, 2), (2, 0))]
    pieces += [np.stack([r.particles[:-1], r.particles[1:]], 1) for r in scene.ropes]
    edges = np.sort(np.concatenate(pieces), axis=1) if pieces else np.zeros((0, 2), np.int64)
    edges = np.unique(edges, axis=0)
    points = np.unique(np.concatenate([c.particles.ravel() for c in scene.cloths]
                                      + [r.particles for r in scene.ropes]))
    both = np.concatenate([edges, edges[:, ::-1]])
    both = np.concatenate([both, _seam_links(scene, both)])
    start, order = csr_layout(both[:, 0], scene.num_particles, then=both[:, 1])
    return {"points": points, "triangles": triangles, "edges": edges,
            "start": start, "neighbours": both[order, 1], "twin": _twins(scene)}


def _twins(scene):
    """(N,) each particle's seam group's least particle id (its own id where unsewn): the
    particles that seams join, directly or through others, share one."""
    springs = scene.springs
    seams = springs["pairs"][springs["kind"] == KIND_CODE["seam"]]
    twin = np.arange(scene.num_particles)
    changed = len(seams) > 0
    while changed:                  # each pass lowers both ends to their lesser label
        low = np.minimum(twin[seams[:, 0]], twin[seams[:, 1]])
        changed = bool(np.any(low != twin[seams[:, 0]]) or np.any(low != twin[seams[:, 1]]))
        np.minimum.at(twin, seams[:, 0], low)
        np.minimum.at(twin, seams[:, 1], low)
        twin = twin[twin]
    return twin


def _seam_links(scene, both):
    """(L, 2) directed neighbour links that make each seam's pair (a, b) one particle: a-b
    and, for every mesh neighbour p of a, p-b (and of b, p-a), both ways."""
    springs = scene.springs
    seams = springs["pairs"][springs["kind"] == KIND_CODE["seam"]]
    if not len(seams):
        return np.zeros((0, 2), np.int64)
    links = [seams]
    for a, b in ((0, 1), (1, 0)):
        # rows (p, seam end b) for each mesh link (seam end a, p)
        order = np.argsort(both[:, 0], kind="stable")
        keys = both[order, 0]
        lo = np.searchsorted(keys, seams[:, a], "left")
        hi = np.searchsorted(keys, seams[:, a], "right")
        rows = np.repeat(np.arange(len(seams)), hi - lo)
        at = np.concatenate([np.arange(l, h) for l, h in zip(lo, hi)] + [np.zeros(0, int)])
        links.append(np.stack([both[order[at], 1], seams[rows, b]], 1))
    one_way = np.concatenate(links)
    return np.unique(np.concatenate([one_way, one_way[:, ::-1]]), axis=0)


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
        start, neighbours: the mesh neighbour lists (CSR, i32); twin: (N,) each
        particle's seam group (``same``);
        params: (6,) reals in ``PARAMS`` order; settings: the same as a dict;
        point_count, triangle_count, edge_count: sizes;
        normals: a vec3 per particle, the guard's vertex normals at a step's start
        (``normals.vertex_normals``).
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
        self.twin = _upload(ti.i32, topo["twin"], ())
        self.params = _upload(runtime.real(), np.array([self.settings[k] for k in PARAMS]), ())
        self.normals = ti.Vector.field(3, runtime.real(), shape=max(scene.num_particles, 1))

    @ti.func
    def same(self, i, j):
        """i and j are one particle, or one seam's (``_twins``)."""
        return self.twin[i] == self.twin[j]

    @ti.func
    def adjacent(self, i, j):
        """i == j, or j is one of i's mesh neighbours."""
        found = i == j
        for k in range(self.start[i], self.start[i + 1]):
            if self.neighbours[k] == j:
                found = True
        return found

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


def _upload(dtype, values, inner):
    values = np.asarray(values)
    rows = max(len(values), 1)
    field = ti.field(dtype, shape=rows) if not inner else ti.Vector.field(inner[0], dtype,
                                                                           shape=rows)
    if len(values):
        field.from_numpy(values.astype(runtime.numpy_real() if dtype != ti.i32 else np.int32))
    return field
