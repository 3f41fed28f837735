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
    return {"points": points, "triangles": triangles, "edges": edges,
            "start": start, "neighbours": both[order, 1]}


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
        self.params = _upload(runtime.real(), np.array([self.settings[k] for k in PARAMS]), ())
        self.normals = ti.Vector.field(3, runtime.real(), shape=max(scene.num_particles, 1))

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
