"""The window's meshes, in NumPy: each collider's mesh at a time (the shape's own ``mesh``
in ``shapes.SHAPES``, moved with the collider), and the cloth's vertex normals
(``primitives.vertex_normals``, which the USD export shares)."""
import numpy as np

from ..geometry.primitives import tiles, vertex_normals
from ..geometry.shapes import shape_of
from ..render.drawables import collider_moves
from ..scene.meshcollider import world_vertices


def collider_mesh(collider, t, half, tile):
    """(vertices, triangles, colours or None) of a scene collider at time t; a plane is a
    square of side 2 half around its point in tiles of side ``tile``; a mesh collider is
    its mesh where its motion has taken it."""
    if collider["kind"] == "mesh":
        return world_vertices(collider, t), collider["faces"], None
    centre = np.asarray(collider["center"]) + t * np.asarray(collider["velocity"])
    v, tris, colours = shape_of(collider).mesh(collider, half, tile)
    return centre + v, tris, colours


__all__ = ["vertex_normals", "collider_mesh", "collider_moves", "tiles"]
