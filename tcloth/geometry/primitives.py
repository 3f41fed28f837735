"""Triangle meshes of the collider shapes and checkered tiles, in NumPy, for the viewer
(each shape's ``mesh`` in ``shapes.SHAPES`` builds on these), a disc for round cloths,
and the vertex normals of a triangle mesh (the viewer's and the USD export's).
Triangles are wound so that the outside (a tile's normal side, a disc's top) is the
front."""
import numpy as np


def grid_triangles(rows, cols):
    """Two triangles per cell of a (rows + 1) x (cols + 1) vertex grid, wound so that a
    sphere's outside (and a tile's +y side) is the front."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = (r * (cols + 1) + c).ravel()
    b, d = a + 1, a + cols + 1
    return np.concatenate([np.stack([a, b, d], 1), np.stack([b, d + 1, d], 1)])


def rings(theta, sectors):
    """Unit-sphere rings at polar angles theta (rows,1): (rows * (sectors + 1), 3)."""
    phi = np.linspace(0, 2 * np.pi, sectors + 1)[None, :]
    return np.stack([np.sin(theta) * np.cos(phi), np.cos(theta) * np.ones_like(phi),
                     np.sin(theta) * np.sin(phi)], -1).reshape(-1, 3)


def sphere(radius, stacks=16, sectors=32):
    """(vertices, triangles) of a sphere about the origin: ``stacks`` bands of
    ``sectors``."""
    theta = np.linspace(0, np.pi, stacks + 1)[:, None]
    return radius * rings(theta, sectors), grid_triangles(stacks, sectors)


def cylinder(radius, half, sectors=32):
    """A capped cylinder along y."""
    phi = np.linspace(0, 2 * np.pi, sectors + 1)
    ring = np.stack([radius * np.cos(phi), np.zeros_like(phi), radius * np.sin(phi)], 1)
    side = np.concatenate([ring + (0, half, 0), ring - (0, half, 0)])
    caps = np.array([[0, half, 0], [0, -half, 0]])
    v = np.concatenate([side, caps])
    n = sectors + 1
    k = np.arange(sectors)
    tris = np.concatenate([np.stack([k, k + 1, n + k], 1), np.stack([k + 1, n + k + 1, n + k], 1),
                           np.stack([np.full(sectors, 2 * n), k + 1, k], 1),
                           np.stack([np.full(sectors, 2 * n + 1), n + k, n + k + 1], 1)])
    return v, tris


def box(half):
    """An axis-aligned box of half extents ``half`` (3,), four vertices a face."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    faces = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
    v = np.concatenate([corners[list(f)] for f in faces])
    base = 4 * np.arange(6)[:, None]
    tris = np.concatenate([base + (0, 1, 2), base + (0, 2, 3)])
    return v, tris


def tiles(centre, normal, half, size):
    """A checkered square of side 2 half, centred on centre, facing normal: (vertices,
    triangles, colours), tiles of side ``size`` with their own vertices."""
    n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    a = np.cross(n, (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 0.0, 1.0))
    a /= np.linalg.norm(a)
    b = np.cross(a, n)
    k = max(1, min(int(2 * half / size), 32))
    step = 2 * half / k
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    i, j = i.ravel(), j.ravel()
    quad = np.array([(0, 0), (1, 0), (1, 1), (0, 1)])
    s = (i[:, None] + quad[None, :, 0]) * step - half
    t = (j[:, None] + quad[None, :, 1]) * step - half
    v = (np.asarray(centre) + s[..., None] * a + t[..., None] * b).reshape(-1, 3)
    base = 4 * np.arange(k * k)[:, None]
    tris = np.concatenate([base + (0, 2, 1), base + (0, 3, 2)])
    shade = np.where((i + j) % 2 == 0, 0.82, 0.68)
    colours = np.repeat(np.stack([shade, shade, shade * 1.02], 1), 4, axis=0).clip(0, 1)
    return v, tris, colours


def disc(rings, radius, grading=1.0):
    """(vertices (V,3), triangles) of a horizontal disc about the origin (y = 0): a centre
    vertex and rings of 6 k vertices at radius R (k / rings)^grading (grading 1: nearly
    equilateral triangles), each ring turned against the last and joined to it by
    triangles in angular order, counter-clockwise seen from above."""
    pts, faces = [np.zeros(3)], []
    inner, inner_angle = [0], np.zeros(1)
    for k in range(1, rings + 1):
        count = 6 * k
        angle = 0.37 * k + 2 * np.pi * np.arange(count) / count
        r = radius * (k / rings) ** grading
        ring = list(range(len(pts), len(pts) + count))
        pts += list(np.stack([r * np.cos(angle), np.zeros(count), r * np.sin(angle)], 1))
        # the inner ring's angles lifted into [angle[0], angle[0] + 2 pi), in order
        lifted = angle[0] + np.mod(inner_angle - angle[0], 2 * np.pi)
        order = np.argsort(lifted)
        inn, ia = [inner[i] for i in order], lifted[order]
        m = len(inn)
        i = j = 0
        while i < count or j < m:
            next_outer = angle[0] + 2 * np.pi * (i + 1) / count
            next_inner = ia[j + 1] if j + 1 < m else ia[0] + 2 * np.pi
            if j == m or (i < count and next_outer <= next_inner):
                faces.append((ring[i % count], ring[(i + 1) % count], inn[j % m]))
                i += 1
            else:
                faces.append((ring[i % count], inn[(j + 1) % m], inn[j % m]))
                j += 1
        inner, inner_angle = ring, angle
    x = np.array(pts)
    tri = np.array([f for f in faces if len(set(f)) == 3])
    up = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])[:, 1]
    tri[up < 0] = tri[up < 0][:, ::-1]
    return x, tri


def vertex_normals(x, triangles):
    """(N,3) unit area-weighted vertex normals of the triangles (0 where a vertex has
    none)."""
    a, b, c = (x[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    ids = triangles.T.ravel()
    n = np.stack([np.bincount(ids, np.tile(face[:, d], 3), len(x)) for d in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def icosphere(radius, subdivisions):
    """(vertices, triangles) of a sphere about the origin: an icosahedron's 20 faces each
    cut into 4^subdivisions, the vertices pushed onto the sphere; outward-wound, closed,
    no degenerate face (20 4^s triangles)."""
    g = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]],
                 dtype=np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inverse.ravel().reshape(3, -1).T       # (F, 3): edges 01, 12, 20
        v = np.concatenate([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
        f = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1),
                            np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True), f
