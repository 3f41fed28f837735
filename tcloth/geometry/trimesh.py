"""Triangle meshes as obstacles, in NumPy: their topology, whether they are closed, the
normals that sign a distance, and a bounding volume hierarchy over their primitives.

``mesh_topology(triangles)``: the edges, whether every edge has two faces wound against
each other (a closed, consistently wound mesh has an inside) and which faces break that.

``pseudo_normals(vertices, triangles)``: Baerentzen and Aanaes's angle-weighted pseudo
normals (IEEE TVCG 11(3), 2005): a face's normal, an edge's the sum of its two faces',
a vertex's the sum of its faces' normals weighted by their angles there. The sign of
(x - c) . N at the closest point c, with N the pseudo normal of the feature (face, edge
or vertex) c lies on, says whether x is inside a closed mesh, exactly, wherever c is.

``bvh(lo, hi)``: a hierarchy of axis-aligned boxes over primitives given by their boxes,
as an implicit complete binary tree (node 1 the root, node k's children 2k and 2k + 1,
the leaves ``leaves`` .. 2 ``leaves`` - 1, each over LEAF primitives of ``order``):
the primitives sorted along a Morton curve of their boxes' centres, so that each leaf
and each node holds primitives near one another. A build is a sort and log2(leaves)
vectorised merges; ``refit`` recomputes the boxes for moved primitives in the same
order (a deforming obstacle).
"""
import numpy as np

LEAF = 4            # primitives a leaf
MORTON_BITS = 10    # per axis


def mesh_topology(triangles):
    """dict: edges (E, 2) sorted pairs, each once; edge_faces (E,) how many faces hold
    each; closed (every edge in two faces that traverse it in opposite directions);
    crossed: the faces whose winding disagrees with a neighbour's, or that share an edge
    with more than one other face."""
    t = np.asarray(triangles, dtype=np.int64)
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    face = np.tile(np.arange(len(t)), 3)
    undirected = np.sort(directed, axis=1)
    edges, inverse, counts = np.unique(undirected, axis=0, return_inverse=True,
                                       return_counts=True)
    inverse = inverse.ravel()
    # +1 where an edge is traversed low -> high, -1 high -> low: a pair of faces wound
    # alike traverses their shared edge in opposite directions (sum 0)
    direction = np.where(directed[:, 0] < directed[:, 1], 1, -1)
    balance = np.bincount(inverse, weights=direction, minlength=len(edges))
    bad_edge = (counts > 2) | ((counts == 2) & (balance != 0))
    crossed = np.unique(face[bad_edge[inverse]])
    closed = bool(np.all(counts == 2) and not len(crossed))
    return {"edges": edges, "edge_faces": counts, "closed": closed, "crossed": crossed}


def signed_volume(vertices, triangles):
    """The volume a closed mesh's faces enclose, positive when they face outward (m^3)."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(triangles)]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def face_normals(vertices, triangles):
    """(F, 3) unit normals (counter-clockwise faces' fronts) and (F,) areas."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(triangles)]
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(length, 1e-300)[:, None], 0.5 * length


def edge_index(triangles):
    """(3 F,) for each face's edge k (from corner k to corner k + 1), in face order, the id
    of its undirected edge: the faces that share an edge share its id. Topology only, so
    a deforming mesh computes it once."""
    t = np.asarray(triangles, dtype=np.int64)
    directed = np.stack([t, np.roll(t, -1, axis=1)], -1).reshape(-1, 2)
    _, inverse = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True)
    return inverse.ravel()


def _sum_rows(ids, rows, count):
    """(count, 3): rows (N, 3) summed by ids (N,)."""
    return np.stack([np.bincount(ids, rows[:, k], minlength=count) for k in range(3)], -1)


def pseudo_normals(vertices, triangles, edges=None):
    """(face (F, 3), edge (F, 3, 3): the pseudo normal of each face's edge k, from corner
    k to corner k + 1, vertex (V, 3)), unnormalised sums (their directions are what
    count). ``edges``: ``edge_index(triangles)``, where the caller keeps it."""
    x = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    normal, _ = face_normals(x, t)
    corners, angles = [], []
    for k in range(3):
        a, b, c = x[t[:, k]], x[t[:, (k + 1) % 3]], x[t[:, (k + 2) % 3]]
        u, w = b - a, c - a
        cos = np.einsum("ij,ij->i", u, w) / np.maximum(
            np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
        corners.append(t[:, k])
        angles.append(np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * normal)
    vertex = _sum_rows(np.concatenate(corners), np.concatenate(angles), len(x))
    edges = edge_index(t) if edges is None else edges
    sums = _sum_rows(edges, np.repeat(normal, 3, axis=0), int(edges.max(initial=-1)) + 1)
    return normal, sums[edges].reshape(len(t), 3, 3), vertex


def _morton(centres):
    """Morton codes of points, MORTON_BITS a coordinate over their bounding box."""
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    scale = (2 ** MORTON_BITS - 1) / np.maximum(hi - lo, 1e-300)
    q = ((centres - lo) * scale).astype(np.int64)
    code = np.zeros(len(q), dtype=np.int64)
    for bit in range(MORTON_BITS):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


def leaf_count(primitives):
    """The leaves of a hierarchy over that many primitives: a power of two."""
    return 1 << max(int(np.ceil(np.log2(max(-(-primitives // LEAF), 1)))), 0)


def bvh(lo, hi):
    """(order (N,) the primitives in leaf order, node_lo, node_hi (2 L, 3), L leaves)
    over primitives with boxes lo, hi (N, 3) (module docstring); empty nodes have
    lo > hi."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    order = np.argsort(_morton(0.5 * (lo + hi)), kind="stable")
    leaves = leaf_count(len(lo))
    node_lo, node_hi = refit(order, lo, hi, leaves)
    return order, node_lo, node_hi, leaves


def refit(order, lo, hi, leaves):
    """(node_lo, node_hi) of ``bvh``'s tree for primitive boxes lo, hi in ``order``."""
    node_lo = np.full((2 * leaves, 3), np.inf)
    node_hi = np.full((2 * leaves, 3), -np.inf)
    slots = leaves * LEAF
    padded_lo = np.full((slots, 3), np.inf)
    padded_hi = np.full((slots, 3), -np.inf)
    padded_lo[:len(order)], padded_hi[:len(order)] = lo[order], hi[order]
    node_lo[leaves:] = padded_lo.reshape(leaves, LEAF, 3).min(axis=1)
    node_hi[leaves:] = padded_hi.reshape(leaves, LEAF, 3).max(axis=1)
    level = leaves
    while level > 1:
        parents = np.arange(level // 2, level)
        node_lo[parents] = np.minimum(node_lo[2 * parents], node_lo[2 * parents + 1])
        node_hi[parents] = np.maximum(node_hi[2 * parents], node_hi[2 * parents + 1])
        level //= 2
    return node_lo, node_hi
