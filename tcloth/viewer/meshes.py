"""The window's meshes, in NumPy: the cloth's vertex normals and each collider's mesh at a
time (the shape's own ``mesh`` in ``shapes.SHAPES``, moved with the collider)."""
import numpy as np

from ..geometry.primitives import tiles
from ..geometry.shapes import shape_of


def vertex_normals(x, triangles):
    """(N,3) unit area-weighted vertex normals of the triangles (0 where a vertex has
    none)."""
    a, b, c = (x[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    ids = triangles.T.ravel()
    n = np.stack([np.bincount(ids, np.tile(face[:, d], 3), len(x)) for d in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def collider_mesh(collider, t, half, tile):
    """(vertices, triangles, colours or None) of a scene collider at time t; a plane is a
    square of side 2 half around its point in tiles of side ``tile``."""
    centre = np.asarray(collider["center"]) + t * np.asarray(collider["velocity"])
    v, tris, colours = shape_of(collider).mesh(collider, half, tile)
    return centre + v, tris, colours


__all__ = ["vertex_normals", "collider_mesh", "tiles"]
