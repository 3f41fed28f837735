"""Edge-triangle intersections of a cloth state, counted with NumPy alone (independent of
tcloth's contact stage, for tests and benchmarks).

``count_crossings(positions, triangles, edges=None)``: the number of (edge, triangle) pairs
that share no particle and where the edge's segment passes through the triangle. The
edges are the triangles' edges (each once) plus any given (rope segments). A cloth that
passes through itself or another cloth has such pairs; one that is merely folded or
piled has none.

Broad phase: a uniform grid of cells the size of the longest edge; each triangle is listed
in the cells its bounding box overlaps, each edge looks in the cells its box overlaps, and
the pairs found are tested exactly (the segment against the triangle's plane, then the
crossing point's barycentric coordinates, in float64). A segment lying in the triangle's
plane counts as no crossing.

Usage as a tool: python tools/crossings.py STATE.npz (arrays "positions" and "triangles")
"""
import sys

import numpy as np


def triangle_edges(triangles):
    """(E, 2) unique edges of (T, 3) triangles, each sorted."""
    t = np.asarray(triangles, dtype=np.int64)
    if not len(t):
        return np.zeros((0, 2), dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def _cells_of_boxes(lo, hi, cell):
    """For boxes (N, 3) lo/hi: (box index, cell key) for every cell each overlaps."""
    a = np.floor(lo / cell).astype(np.int64)
    b = np.floor(hi / cell).astype(np.int64)
    span = b - a + 1
    owners, keys = [], []
    for di in range(int(span[:, 0].max(initial=1))):
        for dj in range(int(span[:, 1].max(initial=1))):
            for dk in range(int(span[:, 2].max(initial=1))):
                ok = (di < span[:, 0]) & (dj < span[:, 1]) & (dk < span[:, 2])
                c = a[ok] + [di, dj, dk]
                owners.append(np.flatnonzero(ok))
                keys.append((c[:, 0] * 73856093) ^ (c[:, 1] * 19349663) ^ (c[:, 2] * 83492791))
    return np.concatenate(owners), np.concatenate(keys)


def candidate_pairs(x, triangles, edges):
    """(edge ids, triangle ids) whose boxes share a grid cell and that share no particle."""
    if not len(triangles) or not len(edges):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    cell = max(float(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1).max()), 1e-9)
    tri_pts = x[triangles]
    t_owner, t_key = _cells_of_boxes(tri_pts.min(axis=1), tri_pts.max(axis=1), cell)
    e_pts = x[edges]
    e_owner, e_key = _cells_of_boxes(e_pts.min(axis=1), e_pts.max(axis=1), cell)
    order = np.argsort(t_key, kind="stable")
    t_key, t_owner = t_key[order], t_owner[order]
    lo = np.searchsorted(t_key, e_key, side="left")
    hi = np.searchsorted(t_key, e_key, side="right")
    counts = hi - lo
    edge_ids = np.repeat(e_owner, counts)
    starts = np.repeat(lo - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    tri_ids = t_owner[np.arange(counts.sum()) + starts]
    # each pair once, in (edge, triangle) order: one key per pair (a 1-D sort is much
    # faster than np.unique over rows)
    key = np.unique(edge_ids * len(triangles) + tri_ids)
    edge_ids, tri_ids = key // len(triangles), key % len(triangles)
    e, t = edges[edge_ids], triangles[tri_ids]
    shared = (e[:, :1] == t).any(axis=1) | (e[:, 1:] == t).any(axis=1)
    return edge_ids[~shared], tri_ids[~shared]


def crossing_pairs(positions, triangles, edges=None):
    """(K, 2) (edge, triangle) index pairs whose segment passes through the triangle;
    edges default to ``triangle_edges(triangles)`` (extra ones may be appended by the
    caller: rope segments)."""
    x = np.asarray(positions, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = triangle_edges(triangles) if edges is None else np.asarray(edges, np.int64)
    ei, ti = candidate_pairs(x, triangles, edges)
    p, q = x[edges[ei, 0]], x[edges[ei, 1]]
    a, b, c = (x[triangles[ti, k]] for k in range(3))
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
    inside = straddle & (w_a >= 0) & (w_b >= 0) & (w_c >= 0)
    return np.stack([ei[inside], ti[inside]], axis=1)


def count_crossings(positions, triangles, edges=None):
    """How many (edge, triangle) pairs sharing no particle intersect (see the module)."""
    return int(len(crossing_pairs(positions, triangles, edges)))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    with np.load(argv[0]) as z:
        print(f"crossings.count: {count_crossings(z['positions'], z['triangles'])}")


if __name__ == "__main__":
    main()
