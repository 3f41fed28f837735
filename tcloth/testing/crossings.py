"""Edge-triangle intersections of a cloth state, counted with NumPy alone (independent of
tcloth's contact stage: the reference that the tests and benchmarks check it against).

``count_crossings(positions, triangles, edges=None, same=None)``: the number of (edge,
triangle) pairs that share no particle and where the edge's segment passes through the
triangle. The edges are the triangles' edges (each once) plus any given (rope segments).
A cloth that passes through itself or another cloth has such pairs; one that is merely
folded or piled has none. ``same`` gives sewn particles one id (``seam_ids``): an edge
and a triangle joined at a seam touch there by construction, as in the merged mesh.
``seam_ids(pairs, n)``: that id, each particle's least partner through the seams'
(K, 2) pairs.

``count_obstacle_crossings(positions, triangles, obstacle_vertices, obstacle_triangles)``:
the same against a triangle-mesh obstacle: cloth edges through obstacle triangles plus
obstacle edges through cloth triangles (a cloth triangle cut by the obstacle has one or
the other at each end of the cut). ``count_inside(positions, obstacle_vertices,
obstacle_triangles)``: the points strictly inside a closed obstacle (ray parity, see
``inside_mask``). ``count_paths_through(a, b, obstacle_vertices, obstacle_triangles)``:
the segments a -> b (particles' paths, in the obstacle's frame) through its triangles.
``edge_depth(positions, edges, obstacle_vertices, obstacle_triangles)``: how deep the
cloth's edges reach inside a closed obstacle. ``closest_on_triangles(p, a, b, c)``: a
point's closest points on triangles and their distances, by brute force.

Broad phase: a uniform grid; each triangle is listed in the cells its bounding box
overlaps, each edge looks in the cells its box overlaps (only within the region where
both sets lie), and the pairs found are tested exactly (the segment against the
triangle's plane, then the crossing point's barycentric coordinates, in float64). The
cell is the longest edge for a cloth against itself, the longer of the two median edges
against an obstacle. A segment lying in the triangle's plane counts as no crossing.
"""
import numpy as np


def triangle_edges(triangles):
    """(E, 2) unique edges of (T, 3) triangles, each sorted."""
    t = np.asarray(triangles, dtype=np.int64)
    if not len(t):
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    return np.stack(_unique_pairs(e.min(axis=1), e.max(axis=1), int(t.max()) + 1), axis=1)


def _cells_of_boxes(lo, hi, cell):
    """For boxes (N, 3) lo/hi: (box index, cell key) for every cell each overlaps (one
    row per box and cell, so a few large boxes cost their own cells only)."""
    a = np.floor(lo / cell).astype(np.int64)
    span = np.floor(hi / cell).astype(np.int64) - a + 1
    counts = span.prod(axis=1)
    owners = np.repeat(np.arange(len(lo)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    sy, sz = span[owners, 1], span[owners, 2]
    c = a[owners] + np.stack([local // (sy * sz), (local // sz) % sy, local % sz], axis=1)
    return owners, (c[:, 0] * 73856093) ^ (c[:, 1] * 19349663) ^ (c[:, 2] * 83492791)


def box_pairs(a_lo, a_hi, b_lo, b_hi, cell):
    """(i, j), each pair once, in order: box i of A overlaps box j of B (closed boxes:
    touching counts). Found through a uniform grid of size ``cell``: each box listed in
    the cells it overlaps, cut first to the region where both sets lie (so a large box far
    from the other set costs nothing)."""
    empty = np.zeros(0, dtype=np.int64)
    if not len(a_lo) or not len(b_lo):
        return empty, empty
    lo = np.maximum(a_lo.min(axis=0), b_lo.min(axis=0))
    hi = np.minimum(a_hi.max(axis=0), b_hi.max(axis=0))
    if (lo > hi).any():
        return empty, empty
    a_ids = np.flatnonzero(((a_lo <= hi) & (a_hi >= lo)).all(axis=1))
    b_ids = np.flatnonzero(((b_lo <= hi) & (b_hi >= lo)).all(axis=1))
    b_owner, b_key = _cells_of_boxes(np.maximum(b_lo[b_ids], lo), np.minimum(b_hi[b_ids], hi),
                                     cell)
    a_owner, a_key = _cells_of_boxes(np.maximum(a_lo[a_ids], lo), np.minimum(a_hi[a_ids], hi),
                                     cell)
    order = np.argsort(b_key, kind="stable")
    b_key, b_owner = b_key[order], b_owner[order]
    first = np.searchsorted(b_key, a_key, side="left")
    counts = np.searchsorted(b_key, a_key, side="right") - first
    i = np.repeat(a_owner, counts)
    starts = np.repeat(first - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    i, j = a_ids[i], b_ids[b_owner[np.arange(counts.sum()) + starts]]
    overlap = ((a_lo[i] <= b_hi[j]) & (b_lo[j] <= a_hi[i])).all(axis=1)
    return _unique_pairs(i[overlap], j[overlap], len(b_lo))


def _unique_pairs(i, j, m):
    """The pairs (i, j), j < m, each once, in order (one key per pair: a 1-D sort is much
    faster than np.unique over rows)."""
    key = np.sort(i * m + j)
    key = key[np.concatenate([key[:1] == key[:1], key[1:] != key[:-1]])]
    return key // m, key % m


def _boxes(points):
    """(lo, hi) of (N, K, 3) point groups (segments, triangles)."""
    return points.min(axis=1), points.max(axis=1)


def candidate_pairs(x, triangles, edges):
    """(edge ids, triangle ids) whose boxes overlap and that share no particle."""
    if not len(triangles) or not len(edges):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    cell = max(float(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1).max()), 1e-9)
    edge_ids, tri_ids = box_pairs(*_boxes(x[edges]), *_boxes(x[triangles]), cell)
    e, t = edges[edge_ids], triangles[tri_ids]
    shared = (e[:, :1] == t).any(axis=1) | (e[:, 1:] == t).any(axis=1)
    return edge_ids[~shared], tri_ids[~shared]


def segments_through_triangles(p, q, a, b, c):
    """For rows of segments pq and triangles abc: does the segment pass through the
    triangle (its ends strictly on either side of the plane, the crossing point inside or
    on the triangle's border)? A segment in the triangle's plane does not."""
    n = np.cross(b - a, c - a)
    dp = np.einsum("ij,ij->i", p - a, n)
    dq = np.einsum("ij,ij->i", q - a, n)
    straddle = dp * dq < 0.0
    s = np.where(straddle, dp / np.where(straddle, dp - dq, 1.0), 0.0)
    hit = p + s[:, None] * (q - p)
    # barycentric coordinates of the crossing point (signed areas against the normal)
    w_a = np.einsum("ij,ij->i", np.cross(b - hit, c - hit), n)
    w_b = np.einsum("ij,ij->i", np.cross(c - hit, a - hit), n)
    w_c = np.einsum("ij,ij->i", np.cross(a - hit, b - hit), n)
    return straddle & (w_a >= 0) & (w_b >= 0) & (w_c >= 0)


def _crossing_rows(xe, edges, xt, triangles, ei, ti):
    """The (edge, triangle) rows of candidates ei, ti whose segment passes through."""
    a, b, c = (xt[triangles[ti, k]] for k in range(3))
    inside = segments_through_triangles(xe[edges[ei, 0]], xe[edges[ei, 1]], a, b, c)
    return np.stack([ei[inside], ti[inside]], axis=1)


def crossing_pairs(positions, triangles, edges=None):
    """(K, 2) (edge, triangle) index pairs whose segment passes through the triangle;
    edges default to ``triangle_edges(triangles)`` (extra ones may be appended by the
    caller: rope segments)."""
    x = np.asarray(positions, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = triangle_edges(triangles) if edges is None else np.asarray(edges, np.int64)
    ei, ti = candidate_pairs(x, triangles, edges)
    return _crossing_rows(x, edges, x, triangles, ei, ti)


def seam_ids(pairs, n):
    """(n,) each particle's least id among the particles that seams (K, 2) join to it,
    directly or through others (its own where unsewn)."""
    ids = np.arange(n)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    for _ in range(len(pairs) + 1):          # each pass lowers both ends to their lesser
        low = np.minimum(ids[pairs[:, 0]], ids[pairs[:, 1]])
        if np.array_equal(low, ids[pairs[:, 0]]) and np.array_equal(low, ids[pairs[:, 1]]):
            break
        ids[pairs[:, 0]] = low
        ids[pairs[:, 1]] = low
    return ids


def count_crossings(positions, triangles, edges=None, same=None):
    """How many (edge, triangle) pairs sharing no particle intersect (see the module);
    ``same``: None, or (N,) an id per particle (a sewn scene's particles, each seam's
    pair under one id): pairs that share an id are left out too."""
    rows = crossing_pairs(positions, triangles, edges)
    if same is None or not len(rows):
        return int(len(rows))
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = triangle_edges(triangles) if edges is None else np.asarray(edges, np.int64)
    e, t = same[edges[rows[:, 0]]], same[triangles[rows[:, 1]]]
    return int((~(e[:, :, None] == t[:, None, :]).any(axis=(1, 2))).sum())


def _median_edge(x, edges):
    return float(np.median(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)))


def obstacle_crossing_pairs(positions, triangles, obstacle_vertices, obstacle_triangles):
    """Two (K, 2) arrays: (cloth edge, obstacle triangle) pairs where the cloth's edge
    passes through the obstacle's triangle, and (obstacle edge, cloth triangle) pairs
    where the obstacle's edge passes through the cloth's triangle. Edges are
    ``triangle_edges`` of either mesh; the grid's cell is the longer of the two meshes'
    median edges."""
    x = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    ov = np.asarray(obstacle_vertices, dtype=np.float64)
    otri = np.asarray(obstacle_triangles, dtype=np.int64).reshape(-1, 3)
    edges, o_edges = triangle_edges(tri), triangle_edges(otri)
    if not len(edges) or not len(o_edges):
        return np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64)
    cell = max(_median_edge(x, edges), _median_edge(ov, o_edges), 1e-9)
    found = []
    for xe, e, xt, t in ((x, edges, ov, otri), (ov, o_edges, x, tri)):
        ei, ti = box_pairs(*_boxes(xe[e]), *_boxes(xt[t]), cell)
        found.append(_crossing_rows(xe, e, xt, t, ei, ti))
    return found[0], found[1]


def count_obstacle_crossings(positions, triangles, obstacle_vertices, obstacle_triangles):
    """How many cloth edges pass through obstacle triangles plus how many obstacle edges
    pass through cloth triangles (``obstacle_crossing_pairs``, both counted)."""
    cloth_through, obstacle_through = obstacle_crossing_pairs(
        positions, triangles, obstacle_vertices, obstacle_triangles)
    return int(len(cloth_through) + len(obstacle_through))


def count_paths_through(a, b, obstacle_vertices, obstacle_triangles):
    """How many segments a[i] -> b[i] ((N, 3) each: particles' paths over a step, in the
    obstacle's frame) pass through one or more of the obstacle's triangles."""
    v = np.asarray(obstacle_vertices, dtype=np.float64)
    tri = v[np.asarray(obstacle_triangles, dtype=np.int64).reshape(-1, 3)]
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if not len(tri) or not len(a):
        return 0
    cell = max(float(np.median(np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1))), 1e-9)
    i, j = box_pairs(np.minimum(a, b), np.maximum(a, b), tri.min(axis=1), tri.max(axis=1),
                     cell)
    hit = segments_through_triangles(a[i], b[i], tri[j, 0], tri[j, 1], tri[j, 2])
    return int(len(np.unique(i[hit])))


def closest_on_triangles(p, a, b, c):
    """(closest points, their distances) of point p (3,) to triangles a, b, c (F, 3): the
    nearest of the face's plane point where it lies inside and the three edges'; (F, 3)
    and (F,). Points (P, 1, 3) give (P, F, 3) and (P, F), each row one point's."""
    def dot(u, v):
        return np.einsum("...j,...j->...", u, v)
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    q = p - dot(p - a, n)[..., None] * n
    inside = True
    for u, v in ((a, b), (b, c), (c, a)):
        inside = inside & (dot(np.cross(v - u, q - u), n) >= 0)
    best = np.where(inside[..., None], q, np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        s = np.clip(dot(p - u, e) / dot(e, e), 0, 1)
        point = u + s[..., None] * e
        closer = np.linalg.norm(p - point, axis=-1) < np.linalg.norm(p - best, axis=-1)
        best = np.where(closer[..., None], point, best)
    return best, np.linalg.norm(p - best, axis=-1)


def edge_depth(positions, edges, obstacle_vertices, obstacle_triangles, samples=16):
    """The deepest any of the cloth's edges (rows of particle ids) reaches inside the
    closed obstacle, m: each edge sampled at ``samples`` points, each sample inside
    (``inside_mask``) at its distance to the nearest triangle (0 where none is inside)."""
    x = np.asarray(positions, dtype=np.float64)
    v = np.asarray(obstacle_vertices, dtype=np.float64)
    t = np.asarray(obstacle_triangles, dtype=np.int64).reshape(-1, 3)
    s = np.linspace(0.0, 1.0, samples)[None, :, None]
    points = (x[edges[:, 0]][:, None] * (1.0 - s) + x[edges[:, 1]][:, None] * s).reshape(-1, 3)
    deepest = 0.0
    for p in points[inside_mask(points, v, t)]:
        deepest = max(deepest, float(closest_on_triangles(p, v[t[:, 0]], v[t[:, 1]],
                                                          v[t[:, 2]])[1].min()))
    return deepest


def _side_of_edges(v, edges, p):
    """For rows of edges (u < w, as indices into v) and query points p: the side of the
    edge's line on which p lies in the (y, z) projection, +1 or -1, with p moved by
    (eps, eps**2) when it lies on the line (0 only for an edge along x). Both triangles
    on an edge read the same number, so a ray through an edge or a vertex meets the
    triangles around it as the ray moved off it by (eps, eps**2) would: once or not."""
    a, b = v[edges[:, 0]], v[edges[:, 1]]
    by, bz = b[:, 1] - a[:, 1], b[:, 2] - a[:, 2]
    det = by * (p[:, 2] - a[:, 2]) - bz * (p[:, 1] - a[:, 1])
    return np.sign(np.where(det != 0, det, np.where(bz != 0, -bz, by)))


def _rays_through(v, t, p):
    """For rows of triangles t and points p: does the ray from p along +x pass through
    the triangle?"""
    sides = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        u, w = t[:, i], t[:, j]
        flip = np.where(u < w, 1.0, -1.0)
        ordered = np.stack([np.minimum(u, w), np.maximum(u, w)], axis=1)
        sides.append(flip * _side_of_edges(v, ordered, p))
    in_shadow = (sides[0] != 0) & (sides[0] == sides[1]) & (sides[1] == sides[2])
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    ahead = np.einsum("ij,ij->i", a - p, n)
    return in_shadow & (ahead * n[:, 0] > 0)


def _on_triangles(v, t, p):
    """For rows of triangles t and points p: p lies in the triangle (its plane, exactly,
    and inside or on its border)."""
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    on_plane = np.einsum("ij,ij->i", p - a, n) == 0
    w = [np.einsum("ij,ij->i", np.cross(s - p, r - p), n) for s, r in ((b, c), (c, a), (a, b))]
    return on_plane & (w[0] >= 0) & (w[1] >= 0) & (w[2] >= 0) & n.any(axis=1)


def inside_mask(positions, obstacle_vertices, obstacle_triangles):
    """(N,) bool: the point lies strictly inside the closed obstacle: a ray from it along
    +x passes through an odd number of its triangles (each edge's side decided once for
    the triangles on it, so rays through edges and vertices count right), and it does not
    lie on the obstacle's surface. Candidate triangles come from a grid over (y, z) for
    the rays and from the 3-D grid for the surface."""
    x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(obstacle_vertices, dtype=np.float64)
    t = np.asarray(obstacle_triangles, dtype=np.int64).reshape(-1, 3)
    inside = np.zeros(len(x), dtype=bool)
    if not len(t) or not len(x):
        return inside
    cell = max(_median_edge(v, triangle_edges(t)), 1e-9)
    lo, hi = _boxes(v[t])
    # rays: points and boxes flattened onto x = 0, so the pairs are the triangles whose
    # (y, z) box holds the point's (y, z)
    ray_lo = np.column_stack([np.zeros(len(x)), x[:, 1:]])
    ray_hi = ray_lo.copy()
    keep = x[:, 0] <= hi[:, 0].max()
    pi, ti = box_pairs(ray_lo[keep], ray_hi[keep], lo * [0, 1, 1], hi * [0, 1, 1], cell)
    pi = np.flatnonzero(keep)[pi]
    through = _rays_through(v, t[ti], x[pi])
    inside[:] = np.bincount(pi[through], minlength=len(x)) % 2 == 1
    pi, ti = box_pairs(x, x, lo, hi, cell)
    inside[pi[_on_triangles(v, t[ti], x[pi])]] = False
    return inside


def count_inside(positions, obstacle_vertices, obstacle_triangles):
    """How many points lie strictly inside the closed obstacle (``inside_mask``)."""
    return int(inside_mask(positions, obstacle_vertices, obstacle_triangles).sum())
