"""The window's meshes, in NumPy: vertex normals, a checkered square of tiles, and one
mesh function per collider shape, which ``collider_mesh`` picks by the collider's kind."""
import numpy as np


def vertex_normals(x, triangles):
    """(N,3) unit area-weighted vertex normals of the triangles (0 where a vertex has
    none)."""
    a, b, c = (x[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    ids = triangles.T.ravel()
    n = np.stack([np.bincount(ids, np.tile(face[:, d], 3), len(x)) for d in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


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


def _grid_triangles(rows, cols):
    """Two triangles per cell of a (rows + 1) x (cols + 1) vertex grid, wound so that a
    sphere's outside (and a tile's +y side) is the front."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = (r * (cols + 1) + c).ravel()
    b, d = a + 1, a + cols + 1
    return np.concatenate([np.stack([a, b, d], 1), np.stack([b, d + 1, d], 1)])


def _placed(collider, centre, v):
    """Vertices v of a collider's own frame, turned by its rotation and moved to centre."""
    return centre + v @ np.asarray(collider["rotation"]).T


# -- one mesh function per collider shape: (collider, centre, half) -> (vertices, triangles)
def sphere_mesh(collider, centre, half, rings=16, sectors=32):
    """A latitude-longitude sphere of the collider's radius about centre."""
    theta = np.linspace(0, np.pi, rings + 1)[:, None]
    phi = np.linspace(0, 2 * np.pi, sectors + 1)[None, :]
    unit = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta) * np.ones_like(phi),
                     np.sin(theta) * np.sin(phi)], -1).reshape(-1, 3)
    return centre + collider["radius"] * unit, _grid_triangles(rings, sectors)


def plane_mesh(collider, centre, half):
    """A square of side 2 half about the plane's point, facing its normal."""
    v, tris, _ = tiles(centre, collider["normal"], half, 2 * half)
    return v, tris


def box_mesh(collider, centre, half):
    """The box's six faces, two triangles each, with their own vertices (flat shading)."""
    half_extents = np.asarray(collider["half_extents"])
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    corners = signs * half_extents
    faces = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
    v = np.concatenate([corners[list(f)] for f in faces])
    base = 4 * np.arange(6)[:, None]
    tris = np.concatenate([base + (0, 1, 2), base + (0, 2, 3)])
    return _placed(collider, centre, v), tris


def cylinder_mesh(collider, centre, half, sectors=32):
    """The cylinder's side and two capped ends, along its own y axis."""
    radius, half_height = collider["radius"], collider["half_height"]
    phi = np.linspace(0, 2 * np.pi, sectors + 1)
    ring = np.stack([radius * np.cos(phi), np.zeros_like(phi), radius * np.sin(phi)], 1)
    side = np.concatenate([ring + (0, half_height, 0), ring - (0, half_height, 0)])
    caps = np.array([[0, half_height, 0], [0, -half_height, 0]])
    v = np.concatenate([side, caps])
    n = sectors + 1
    k = np.arange(sectors)
    tris = np.concatenate([np.stack([k, k + 1, n + k], 1), np.stack([k + 1, n + k + 1, n + k], 1),
                           np.stack([np.full(sectors, 2 * n), k + 1, k], 1),
                           np.stack([np.full(sectors, 2 * n + 1), n + k, n + k + 1], 1)])
    return _placed(collider, centre, v), tris


COLLIDER_MESHES = {"sphere": sphere_mesh, "plane": plane_mesh, "box": box_mesh,
                   "cylinder": cylinder_mesh}


def collider_mesh(collider, t, half):
    """(vertices, triangles) of a scene collider at time t, by its kind
    (``COLLIDER_MESHES``); planes are a square of side 2 half around their point."""
    centre = np.asarray(collider["center"]) + t * np.asarray(collider["velocity"])
    return COLLIDER_MESHES[collider["kind"]](collider, centre, half)
