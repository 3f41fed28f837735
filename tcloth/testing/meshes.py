"""Obstacle meshes made with NumPy alone, so that a benchmark and its peers (e.g.
tools/newton_mesh_peer.py, which reads this file without importing tcloth) build the
identical triangles. It imports nothing but NumPy.

``sphere_mesh(radius, triangles, center=(0, 0, 0))``: a geodesic sphere (an icosahedron
whose faces are each cut into f x f triangles, the vertices pushed onto the sphere) with
20 f^2 triangles, f chosen so that the count is the closest to ``triangles``: 9,680 for
10,000 and 100,820 for 100,000. Unlike a UV sphere it has no poles, so a cloth dropped on
its top meets triangles of the same size as anywhere else (the largest has about twice the
smallest's area). Faces wind counter-clockwise seen from outside (normals outward).
"""
import numpy as np


def _icosahedron():
    """(12, 3) unit vertices and (20, 3) outward faces of a regular icosahedron."""
    g = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0],
                  [0, -1, g], [0, 1, g], [0, -1, -g], [0, 1, -g],
                  [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], dtype=np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                  [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                  [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                  [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    return v / np.linalg.norm(v, axis=1, keepdims=True), f


def sphere_frequency(triangles):
    """The f >= 1 whose 20 f^2 is the closest to ``triangles`` (the smaller on a tie)."""
    f = max(int(np.sqrt(max(triangles, 1) / 20.0)), 1)
    return min((f, f + 1), key=lambda k: (abs(20 * k * k - triangles), k))


def sphere_mesh(radius, triangles, center=(0.0, 0.0, 0.0)):
    """(V, 3) float64 vertices and (T, 3) int64 faces of a geodesic sphere of ``radius``
    about ``center`` with T = 20 f^2 the closest to ``triangles`` (see the module)."""
    ico, ico_faces = _icosahedron()
    f = sphere_frequency(triangles)
    # lattice points (i, j) with i + j <= f on each face, weights (f - i - j, i, j) on its
    # corners; a point's key is its weights on all 12 corners, so points on a shared edge
    # or corner are found equal exactly
    i, j = (a.ravel() for a in np.meshgrid(np.arange(f + 1), np.arange(f + 1), indexing="ij"))
    keep = i + j <= f
    i, j = i[keep], j[keep]
    local = np.full((f + 1, f + 1), -1)
    local[i, j] = np.arange(len(i))
    # two triangles per lattice cell: (i, j), (i+1, j), (i, j+1) and its upper neighbour
    lo = (i + j) < f
    up = (i + j) < f - 1
    cells = np.concatenate([
        np.stack([local[i[lo], j[lo]], local[i[lo] + 1, j[lo]], local[i[lo], j[lo] + 1]], 1),
        np.stack([local[i[up] + 1, j[up]], local[i[up] + 1, j[up] + 1],
                  local[i[up], j[up] + 1]], 1)])
    weights = np.zeros((20, len(i), 12), dtype=np.int64)
    for k, (a, b, c) in enumerate(ico_faces):
        weights[k, :, a] += f - i - j
        weights[k, :, b] += i
        weights[k, :, c] += j
    keys, index = np.unique(weights.reshape(-1, 12), axis=0, return_inverse=True)
    faces = (index.reshape(20, -1)[:, cells]).reshape(-1, 3)
    points = keys @ ico
    vertices = points / np.linalg.norm(points, axis=1, keepdims=True)
    return radius * vertices + np.asarray(center, dtype=np.float64), faces.astype(np.int64)
