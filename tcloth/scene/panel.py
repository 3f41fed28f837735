"""Garment panels: a 2D polygon outline triangulated into a cloth piece (``tcloth.panel``).

The outline's edges are divided into segments of at most ``resolution`` metres (an edge of
length L into ceil(L / resolution) equal ones, so that two edges of one length get the same
points and sew pair by pair); the inside is filled with a triangular lattice of that
spacing, keeping the lattice points at least 0.6 resolution from the outline, and all the
points are joined by a Delaunay triangulation (Bowyer-Watson), of which the triangles
inside the outline are the panel. Each outline segment is a Delaunay edge where no other
point lies in the circle on it as diameter: the lattice keeps its points out of those
circles, and an outline corner sharper than a right angle can put its neighbour edge's
points in them; a panel whose outline segments are not all triangle edges is refused
(``SceneError``), naming the corner.
"""
import numpy as np

from ..errors import SceneError
from ..validate import as_scalar, as_vec3, fmt


class Panel:
    """A flat cloth piece in its own plane (u, v), m.

    Attributes:
        outline: (K, 2) the outline's corners, counter-clockwise.
        vertices: (V, 2); triangles: (T, 3) vertex ids, counter-clockwise (their normal is
            the panel's +w, ``place``).
        edges: K arrays of vertex ids: edges[k] runs along the outline from corner k to
            corner k + 1 (both included), so that sewing edge k of one panel to edge j of
            another pairs ``edges[k]`` with ``edges[j]`` (or its reverse).
    """

    def __init__(self, outline, vertices, triangles, edges):
        self.outline, self.vertices, self.triangles, self.edges = \
            outline, vertices, triangles, edges

    def place(self, origin=(0.0, 0.0, 0.0), rotation=None):
        """(V, 3) the vertices in the world: origin + R (u, v, 0), R a 3x3 rotation (None:
        the identity, the panel in the xy plane facing +z)."""
        r = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-6):
            raise SceneError(f"rotation must be a 3x3 rotation matrix (got {fmt(rotation)})")
        uvw = np.concatenate([self.vertices, np.zeros((len(self.vertices), 1))], 1)
        return as_vec3("origin", origin) + uvw @ r.T

    def add_to(self, scene, origin=(0.0, 0.0, 0.0), rotation=None, **cloth):
        """Add the panel, placed (``place``), to ``scene`` as a mesh cloth
        (``Scene.add_mesh_cloth``, whose arguments ``cloth`` passes on). Returns the
        MeshCloth with ``edges``: the outline edges' particle ids (as ``Panel.edges``)."""
        mesh = scene.add_mesh_cloth(self.place(origin, rotation),
                                    [tuple(t) for t in self.triangles], **cloth)
        mesh.edges = [mesh.particles[e] for e in self.edges]
        return mesh


def panel(outline, resolution):
    """A triangulated cloth panel of a simple polygon (module docstring).

    Args:
        outline: (K, 2) corners in order, K >= 3, m; either orientation (a clockwise one
            is reversed, and its edges with it: ``Panel.edges`` follows the stored one).
        resolution: the longest outline segment and the lattice's spacing, m, > 0.
    Returns:
        Panel.
    """
    p = _outline(outline)
    h = as_scalar("resolution", resolution, minimum=0.0, strict=True)
    k = len(p)
    seg = np.roll(p, -1, axis=0) - p
    counts = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / h - 1e-9)).astype(int)
    if counts.sum() > 100000:
        raise SceneError(f"resolution={h} makes {counts.sum()} outline points: too fine "
                         f"for an outline this size")
    boundary = np.concatenate([p[i] + np.arange(counts[i])[:, None] / counts[i] * seg[i]
                               for i in range(k)])
    starts = np.concatenate([[0], np.cumsum(counts)])
    nb = len(boundary)
    edges = [np.arange(starts[i], starts[i] + counts[i] + 1) % nb for i in range(k)]
    points = np.concatenate([boundary, _lattice(p, h)])
    # the triangulation of points moved by 1e-9 h at random (fixed seed): the outline's
    # collinear and the lattice's cocircular points would meet the in-circle test with
    # ties; the slivers that this leaves along straight edges (three of one edge's points)
    # have next to no area and are dropped
    jitter = np.random.default_rng(0).uniform(-1e-9 * h, 1e-9 * h, points.shape)
    triangles = _delaunay(points + jitter)
    centroid = points[triangles].mean(axis=1)
    e1, e2 = (points[triangles[:, i]] - points[triangles[:, 0]] for i in (1, 2))
    area = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    triangles = triangles[_inside(centroid, p) & (area > 1e-6 * h * h)]
    _check_segments(triangles, nb, boundary, p, starts)
    used = np.zeros(len(points), bool)
    used[triangles] = True
    keep = np.cumsum(used) - 1
    return Panel(p, points[used], keep[triangles], [keep[e] for e in edges])


def _outline(outline):
    try:
        p = np.asarray(outline, dtype=np.float64)
    except (TypeError, ValueError):
        p = None
    if p is None or p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.isfinite(p).all():
        raise SceneError(f"outline must be (K, 2) finite corners, K >= 3 (got {fmt(outline)})")
    area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    if abs(area) <= 1e-12 * np.ptp(p, axis=0).max() ** 2:
        raise SceneError(f"outline encloses no area (got {fmt(outline)})")
    k = len(p)
    for i in range(k):
        for j in range(i + 1, k):
            if j == i + 1 or (i == 0 and j == k - 1):
                if np.allclose(p[i], p[j]):
                    raise SceneError(f"outline corners {i} and {j} coincide")
                continue
            if _segments_cross(p[i], p[(i + 1) % k], p[j], p[(j + 1) % k]):
                raise SceneError(f"outline edges {i} and {j} cross (the outline must be a "
                                 f"simple polygon)")
    return p if area > 0 else p[::-1].copy()


def _segments_cross(a, b, c, d):
    def side(p, q, r):
        return np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))
    return side(a, b, c) != side(a, b, d) and side(c, d, a) != side(c, d, b)


def _inside(q, p):
    """Whether each point of q (M, 2) is inside polygon p (even-odd rule)."""
    a, b = p, np.roll(p, -1, axis=0)
    y = q[:, 1:2]
    spans = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) \
            / (b[None, :, 1] - a[None, :, 1])
    return (np.sum(spans & (q[:, 0:1] < x), axis=1) % 2) == 1


def _distance_to_outline(q, p):
    a, b = p, np.roll(p, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("mkd,kd->mk", q[:, None] - a[None], ab) / np.sum(ab * ab, 1), 0, 1)
    nearest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(q[:, None] - nearest, axis=2).min(axis=1)


def _lattice(p, h):
    """Triangular-lattice points of spacing h inside p, at least 0.6 h from its edges."""
    lo, hi = p.min(axis=0), p.max(axis=0)
    rows = np.arange(lo[1], hi[1] + h, h * np.sqrt(3) / 2)
    cols = np.arange(lo[0] - h, hi[0] + h, h)
    pts = np.concatenate([np.stack([cols + (0.5 * h if r % 2 else 0.0),
                                    np.full(len(cols), y)], 1) for r, y in enumerate(rows)])
    pts = pts[_inside(pts, p)]
    return pts[_distance_to_outline(pts, p) >= 0.6 * h]


def _delaunay(points):
    """(T, 3) counter-clockwise Delaunay triangles of 2D points (Bowyer-Watson)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    c, s = 0.5 * (lo + hi), 10.0 * np.ptp(points, axis=0).max()
    pts = np.concatenate([points, c + s * np.array([[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]])])
    n = len(points)
    first = _circumcircle(pts, n, n + 1, n + 2)
    tri, centre, radius2, alive = [(n, n + 1, n + 2)], [first[0]], [first[1]], [True]
    for i in range(n):
        cc, r2 = np.array(centre), np.array(radius2)
        bad = np.flatnonzero(np.array(alive) & (np.sum((cc - pts[i]) ** 2, 1) < r2))
        count = {}
        for t in bad:
            alive[t] = False
            a, b, d = tri[t]
            for e in ((a, b), (b, d), (d, a)):
                key = (min(e), max(e))
                count[key] = (e, count.get(key, (e, 0))[1] + 1)
        for e, k in count.values():
            if k == 1:
                tri.append((e[0], e[1], i))
                c_, r_ = _circumcircle(pts, e[0], e[1], i)
                centre.append(c_)
                radius2.append(r_)
                alive.append(True)
    tri = np.array(tri)[np.array(alive)]
    return tri[(tri < n).all(axis=1)]


def _circumcircle(pts, i, j, k):
    a, b, c = pts[i], pts[j], pts[k]
    d = 2.0 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    ba, ca = b - a, c - a
    ux = (ca[1] * ba.dot(ba) - ba[1] * ca.dot(ca)) / d
    uy = (ba[0] * ca.dot(ca) - ca[0] * ba.dot(ba)) / d
    return a + np.array([ux, uy]), ux * ux + uy * uy


def _check_segments(triangles, nb, boundary, corners, starts):
    """Refuse a triangulation missing an outline segment (i, i + 1)."""
    have = {(min(e), max(e)) for t in triangles for e in ((t[0], t[1]), (t[1], t[2]),
                                                          (t[2], t[0]))}
    for i in range(nb):
        j = (i + 1) % nb
        if (min(i, j), max(i, j)) not in have:
            corner = int(np.searchsorted(starts, i, side="right") - 1)
            raise SceneError(f"the outline's edge {corner} (from corner {corner}, "
                             f"{corners[corner].tolist()}) is not triangulated along its "
                             f"length near {boundary[i].tolist()}: a corner sharper than a "
                             f"right angle next to it, or a resolution coarse for it; "
                             f"give a smaller resolution or blunter corners")
