"""Builders: Provot cloth grids, cloth from meshes and ropes, added to a Scene as particles
and springs."""
import os

import numpy as np

from . import fabric as fabrics
from . import hinges
from ..errors import SceneError
from .objfile import read_obj
from .usdfile import is_usd, read_usd
from ..validate import (as_int, as_per_item, as_points, as_rotation, as_scalar, as_spring_params,
                        as_vec3, fmt)


class _Unset:
    """The default of a Provot cloth's mass and spring families, told apart from a value
    given beside a fabric."""

    def __init__(self, value):
        self.value = value

    def __repr__(self):
        return repr(self.value)


def unset(value):
    """A default that ``classic`` resolves, shown as ``value`` in signatures."""
    return _Unset(value)


def classic(fabric, **given):
    """The given mass and spring families, defaults filled in; SceneError when any of
    them is given beside a fabric."""
    if fabric is not None:
        named = [k for k, v in given.items() if not isinstance(v, _Unset)]
        if named:
            raise SceneError(f"give either fabric or {', '.join(named)} (got both): the "
                             "fabric sets the masses and springs")
    return {k: v.value if isinstance(v, _Unset) else v for k, v in given.items()}


class Cloth:
    """A Provot cloth on a regular grid, as added by ``Scene.add_cloth`` (``is_grid``).

    Attributes:
        particles: (ny, nx) int array of particle ids; row j, column i.
        triangles: (T, 3) int array of particle ids, counter-clockwise seen from the front.
        springs: dict family -> (M_family,) int array of spring ids.
        resolution: (nx, ny); spacing: (dx, dy) in metres; offset: id of particle (0, 0).
        params: dict family -> (k_s, k_d) or None (a fabric cloth: its interior springs').
        stencil: its springs are one (k_s, k_d) per family, evaluated by the grid stencil;
            False for a fabric cloth (border springs differ), whose springs are a list.
        uv: (T, 3, 2) texture coordinates at the triangles' corners: u = i / (nx - 1)
            along the grid's columns, v = 1 - j / (ny - 1) (row 0, an xy grid's top, at v = 1).
    """

    is_grid = True

    def __init__(self, offset, resolution, spacing, params, plane, stencil=True):
        self.stencil = stencil
        self.offset = offset
        self.resolution = resolution
        self.spacing = spacing
        self.params = params
        self.plane = plane
        nx, ny = resolution
        self.particles = offset + np.arange(nx * ny).reshape(ny, nx)
        p = self.particles
        a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
        self.triangles = np.concatenate([
            np.stack([a, d, b], -1).reshape(-1, 3),
            np.stack([b, d, c], -1).reshape(-1, 3)])
        self.springs = {}

    def grid_pairs(self, family):
        """(M,2) particle pairs of one Provot family on this grid."""
        p = self.particles
        if family == "structural":
            parts = [(p[:, :-1], p[:, 1:]), (p[:-1, :], p[1:, :])]
        elif family == "shear":
            parts = [(p[:-1, :-1], p[1:, 1:]), (p[:-1, 1:], p[1:, :-1])]
        elif family == "flexion":
            parts = [(p[:, :-2], p[:, 2:]), (p[:-2, :], p[2:, :])]
        else:
            raise SceneError(f"family must be structural, shear or flexion (got {family!r})")
        return np.concatenate([np.stack([u.ravel(), v.ravel()], 1) for u, v in parts])

    @property
    def uv(self):
        nx, ny = self.resolution
        u, v = np.meshgrid(np.linspace(0.0, 1.0, nx), np.linspace(1.0, 0.0, ny))
        return np.stack([u.ravel(), v.ravel()], 1)[self.triangles - self.offset]


class MeshCloth:
    """A cloth made from a triangle or polygon mesh, as added by ``Scene.add_mesh_cloth``.

    Attributes:
        particles: (V,) particle ids in vertex order; offset: the first of them.
        triangles: (T, 3) particle ids, the faces fanned into triangles (v0, vi, vi+1),
            counter-clockwise seen from the front as in the file.
        springs: dict family -> (M_family,) spring ids. params: family -> (k_s, k_d) or None.
        uv: (T, 3, 2) texture coordinates at the triangles' corners, or None (the mesh
            had none).
    """
    is_grid = False

    def __init__(self, offset, count, triangles, params, uv=None):
        self.offset = offset
        self.particles = offset + np.arange(count)
        self.triangles = offset + np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        self.params = params
        self.springs = {}
        self.uv = None if uv is None else np.asarray(uv, dtype=np.float64).reshape(-1, 3, 2)


def fan(faces):
    """(T, 3) triangles of polygons fanned from their first vertex, and for each the
    face it came from."""
    tris, owner = [], []
    for k, face in enumerate(faces):
        for i in range(1, len(face) - 1):
            tris.append((face[0], face[i], face[i + 1]))
            owner.append(k)
    return np.array(tris, dtype=np.int64).reshape(-1, 3), np.array(owner, dtype=np.int64)


def _pairs(pairs):
    """Unique unordered pairs, each (low, high), sorted."""
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    return np.unique(pairs, axis=0)


def mesh_springs(faces, triangles):
    """dict family -> (M, 2) vertex pairs of a mesh (see ``Scene.add_mesh_cloth``):
    structural on the faces' edges, shear across the diagonals of quads, flexion between
    the two vertices opposite each interior edge (the fanned triangles on its two sides),
    leaving out pairs already joined by a structural or shear spring."""
    edges = [(f[i], f[(i + 1) % len(f)]) for f in faces for i in range(len(f))]
    key = np.sort(np.array(edges, dtype=np.int64), axis=1)
    unique, counts = np.unique(key, axis=0, return_counts=True)
    if counts.max() > 2:
        a, b = unique[np.argmax(counts)]
        raise SceneError(f"the mesh is not manifold: edge ({a}, {b}) is shared by "
                         f"{counts.max()} faces (at most 2)")
    structural = unique
    shear = _pairs([(f[0], f[2]) for f in faces if len(f) == 4]
                   + [(f[1], f[3]) for f in faces if len(f) == 4])
    opposite = {}
    for tri in triangles:
        for i in range(3):
            a, b = sorted((tri[i], tri[(i + 1) % 3]))
            opposite.setdefault((a, b), []).append(tri[(i + 2) % 3])
    interior = [tuple(e) for e, c in zip(unique, counts) if c == 2]
    flexion = _pairs([opposite[e] for e in interior if len(opposite[e]) == 2])
    taken = {tuple(p) for p in structural} | {tuple(p) for p in shear}
    flexion = np.array([p for p in flexion if tuple(p) not in taken and p[0] != p[1]],
                       dtype=np.int64).reshape(-1, 2)
    return {"structural": structural, "shear": shear, "flexion": flexion}


def check_faces(x, faces):
    """(the faces as tuples of vertex ids, their fan triangles (T,3), each vertex's share
    of the faces' area) of a mesh with vertices x, every face checked: ids in range, no
    repeat, no zero area, no vertex outside every face."""
    n = len(x)
    checked = []
    for k, face in enumerate(faces):
        f = np.asarray(face)
        if f.ndim != 1 or len(f) < 3 or f.dtype.kind not in "iu":
            raise SceneError(f"faces[{k}] must be 3 or more vertex ids (got {fmt(face)})")
        if f.min() < 0 or f.max() >= n:
            raise SceneError(f"faces[{k}] = {f.tolist()} has a vertex id outside [0, {n})")
        if len(set(f.tolist())) != len(f):
            raise SceneError(f"faces[{k}] = {f.tolist()} repeats a vertex")
        checked.append(tuple(int(i) for i in f))
    triangles, owner = fan(checked)
    e1, e2 = x[triangles[:, 1]] - x[triangles[:, 0]], x[triangles[:, 2]] - x[triangles[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    scale = np.ptp(x, axis=0).max() ** 2
    bad = np.flatnonzero(area <= 1e-12 * scale)
    if len(bad):
        raise SceneError(f"faces[{owner[bad[0]]}] = {list(checked[owner[bad[0]]])} is "
                         f"degenerate (zero area)")
    face_area = np.bincount(owner, weights=area, minlength=len(checked))
    vertex_area = np.zeros(n)
    for face, a in zip(checked, face_area):
        vertex_area[list(face)] += a / len(face)
    lonely = np.flatnonzero(vertex_area == 0.0)
    if len(lonely):
        raise SceneError(f"vertex {lonely[0]} is in no face (every vertex must be)")
    return checked, triangles, vertex_area


def read_mesh(path, prim=None):
    """(vertices, faces, texture coordinates a face or None) of an OBJ or USD file."""
    if is_usd(path):
        return read_usd(path, prim)
    if prim is not None:
        raise SceneError(f"prim names a mesh in a USD file (.usd, .usda, .usdc, .usdz); "
                         f"{str(path)!r} is not one (got prim={prim!r})")
    return read_obj(path)


def triangle_uvs(uvs, faces, n):
    """(T, 3, 2) texture coordinates at the corners of the faces' fan triangles, of
    ``uvs``: (n, 2), one a vertex, or one (len(face), 2) array a face; None: None."""
    if uvs is None:
        return None
    try:
        per_vertex = np.asarray(uvs, dtype=np.float64)
    except (TypeError, ValueError):
        per_vertex = None
    if per_vertex is not None and per_vertex.shape == (n, 2):
        corners = per_vertex[np.concatenate(faces)]
    else:
        try:
            corners = [np.asarray(u, dtype=np.float64) for u in uvs]
        except (TypeError, ValueError):
            corners = None
        if corners is None or len(corners) != len(faces):
            bad = f"got {fmt(uvs)}" if corners is None else \
                f"got {len(corners)} arrays for {len(faces)} faces"
        else:
            bad = next((f"face {k} has {len(f)} corners, its array shape {c.shape}"
                        for k, (c, f) in enumerate(zip(corners, faces))
                        if c.shape != (len(f), 2)), None)
        if bad:
            raise SceneError(f"uvs must be ({n}, 2), a (u, v) a vertex, or one (n, 2) array "
                             f"a face for its n corners ({bad})")
        corners = np.concatenate(corners)
    if not np.all(np.isfinite(corners)):
        raise SceneError(f"uvs must be finite (got {fmt(uvs)})")
    starts = np.cumsum([0] + [len(f) for f in faces[:-1]])
    return corners[fan([range(s, s + len(f)) for s, f in zip(starts, faces)])[0]]


def add_mesh_cloth(scene, vertices, faces, mass, structural, shear, flexion, pinned,
                   fabric=None, uvs=None, prim=None):
    """``Scene.add_mesh_cloth``: particles at the vertices, springs from the faces (a
    fabric's: the triangle membrane and hinge bending, ``fabric.py``)."""
    fabric = None if fabric is None else fabrics.preset(fabric)
    given = classic(fabric, mass=mass, structural=structural, shear=shear, flexion=flexion)
    if isinstance(vertices, (str, os.PathLike)):
        if faces is not None or uvs is not None:
            raise SceneError("give either a path or vertices and faces (got a path and "
                             f"{'faces' if faces is not None else 'uvs'})")
        vertices, faces, uvs = read_mesh(vertices, prim)
    elif prim is not None:
        raise SceneError(f"prim names a mesh in a USD file: give it with the file's path "
                         f"(got prim={prim!r} with vertices and faces)")
    x = as_points("vertices", vertices)
    if faces is None or len(faces) == 0:
        raise SceneError("faces must list at least one face (got none)")
    n = len(x)
    checked, triangles, vertex_area = check_faces(x, faces)
    uv = triangle_uvs(uvs, checked, n)
    springs = mesh_springs(checked, triangles)      # refuses a mesh that is not manifold
    if fabric is not None:
        masses = fabric.density * vertex_area
        params = {"structural": None, "shear": None, "flexion": None}
    elif np.ndim(given["mass"]) == 0:
        masses = as_scalar("mass", given["mass"], minimum=0.0, strict=True) * vertex_area \
            / vertex_area.sum()
    else:
        masses = as_per_item("mass", given["mass"], n, minimum=0.0, strict=True)
    if fabric is None:
        params = {family: as_spring_params(family, given[family])
                  for family in ("structural", "shear", "flexion")}
    pin = np.zeros(n, dtype=bool)
    ids = np.asarray(list(pinned) if pinned is not None else [], dtype=np.int64)
    if ids.ndim != 1 or (len(ids) and (ids.min() < 0 or ids.max() >= n)):
        raise SceneError(f"pinned must be vertex ids in [0, {n}) (got {fmt(pinned)})")
    pin[ids] = True
    cloth = MeshCloth(scene.num_particles, n, triangles, params, uv)
    if fabric is not None and max(fabric.bending) > 0:     # checked before anything is added
        rest = np.concatenate([scene.positions, x])
        try:
            hinges.check_flat(*hinges.hinge_table(cloth.triangles, rest)[::3])
        except SceneError as e:
            raise SceneError(
                f"{e}: a fabric with bending > 0 needs a flat mesh; a closed or curved mesh "
                f"(a balloon) takes one with bending=0, the membrane alone, which keeps any "
                f"rest shape: tcloth.Fabric(..., bending=0), or fabric.without_bending() "
                f"({fabric.name!r} without its bending)") from None
        hinges.cloth_hinges(cloth, rest, fabric.bending)
    scene.add_particles(x, mass=masses, pinned=pin)
    if fabric is not None:
        cloth.springs.update({family: np.zeros(0, dtype=np.int64) for family in params})
        return _finish_fabric(scene, cloth, fabric)
    for family, pairs in springs.items():
        kskd = params[family]
        if kskd is None or len(pairs) == 0:
            cloth.springs[family] = np.zeros(0, dtype=np.int64)
            continue
        cloth.springs[family] = scene.add_springs(pairs + cloth.offset, kskd[0], kskd[1],
                                                  kind=family)
    scene.cloths.append(cloth)
    return cloth


class Rope:
    """A chain of particles joined by springs, as added by ``Scene.add_rope``.

    Attributes: particles (segments+1,) ids from start to end; springs (segments,) ids.
    """

    def __init__(self, particles, springs):
        self.particles = particles
        self.springs = springs


def add_cloth(scene, resolution, size, center, plane, mass, structural, shear, flexion,
              pinned, rotation=None, fabric=None):
    """``Scene.add_cloth``: the particles and springs of a Provot cloth grid, or of a
    fabric's grid (``fabric.py``). ``pinned`` None (the default, with or without a
    fabric) pins the corners (0, 0) and (nx - 1, 0), as the API has it; [] pins none."""
    fabric = None if fabric is None else fabrics.preset(fabric)
    given = classic(fabric, mass=mass, structural=structural, shear=shear, flexion=flexion)
    if np.ndim(resolution) != 1 or len(resolution) != 2:
        raise SceneError(f"resolution must be a pair (nx, ny) (got {fmt(resolution)})")
    nx = as_int("resolution[0] (nx)", resolution[0], 2)
    ny = as_int("resolution[1] (ny)", resolution[1], 2)
    if np.ndim(size) != 1 or len(size) != 2:
        raise SceneError(f"size must be a pair (w, h) (got {fmt(size)})")
    w = as_scalar("size[0] (w)", size[0], minimum=0.0, strict=True)
    h = as_scalar("size[1] (h)", size[1], minimum=0.0, strict=True)
    c = as_vec3("center", center)
    if plane not in ("xz", "xy"):
        raise SceneError(f"plane must be 'xz' or 'xy' (got {plane!r})")
    if fabric is None:
        total = as_scalar("mass", given["mass"], minimum=0.0, strict=True)
        params = {family: as_spring_params(family, given[family])
                  for family in ("structural", "shear", "flexion")}
    pins = [(0, 0), (nx - 1, 0)] if pinned is None else list(pinned)
    pin = np.zeros((ny, nx), dtype=bool)
    for k, ij in enumerate(pins):
        if np.ndim(ij) != 1 or len(ij) != 2 or not all(
                isinstance(t, (int, np.integer)) for t in ij):
            raise SceneError(f"pinned[{k}] must be an (i, j) pair of ints (got {fmt(ij)})")
        i, j = int(ij[0]), int(ij[1])
        if not (0 <= i < nx and 0 <= j < ny):
            raise SceneError(f"pinned[{k}] = {(i, j)} is outside the {nx} x {ny} grid")
        pin[j, i] = True
    dx, dy = w / (nx - 1), h / (ny - 1)
    ii, jj = np.meshgrid(np.arange(nx) * dx - w / 2, np.arange(ny) * dy - h / 2)
    if plane == "xz":
        pos = np.stack([ii, np.zeros_like(ii), jj], -1)
    else:
        pos = np.stack([ii, -jj, np.zeros_like(ii)], -1)
    pos = pos.reshape(-1, 3)
    if rotation is not None:
        pos = pos @ as_rotation("rotation", rotation).T
    if fabric is not None:
        return _fabric_grid(scene, fabric, (nx, ny), (dx, dy), plane, pos + c, pin.ravel())
    cloth = Cloth(scene.num_particles, (nx, ny), (dx, dy), params, plane)
    scene.add_particles(pos + c, mass=total / (nx * ny), pinned=pin.ravel())
    for family, kskd in params.items():
        pairs = cloth.grid_pairs(family)
        if kskd is None or len(pairs) == 0:
            cloth.springs[family] = np.zeros(0, dtype=np.int64)
            continue
        cloth.springs[family] = scene.add_springs(pairs, kskd[0], kskd[1], kind=family)
    scene.cloths.append(cloth)
    return cloth


def _fabric_grid(scene, fabric, resolution, spacing, plane, positions, pinned):
    """A grid cloth of a fabric: area-weighted masses, border-halved structural and shear
    springs with damping as a ratio of critical, hinge bending (``fabric.py``)."""
    cloth = Cloth(scene.num_particles, resolution, spacing, {}, plane, stencil=False)
    springs = fabrics.grid_springs(fabric, cloth)   # may refuse: before anything is added
    masses = fabrics.grid_masses(fabric, *resolution, *spacing).ravel()
    scene.add_particles(positions, mass=masses, pinned=pinned)
    m = scene.masses
    for family, (pairs, ks) in springs.items():
        damp = fabrics.damping(fabric, ks, m, pairs)
        cloth.springs[family] = scene.add_springs(pairs, ks, damp, kind=family)
        cloth.params[family] = (float(np.max(ks)), float(np.max(damp)))
    cloth.params["flexion"] = None
    cloth.springs["flexion"] = np.zeros(0, dtype=np.int64)
    return _finish_fabric(scene, cloth, fabric)


def _finish_fabric(scene, cloth, fabric):
    """Append a fabric's cloth and add it, at rest at its positions now, to the scene's
    hinge bending (``Scene.set_bending``) and, a mesh cloth, to its triangle membrane
    (``Scene.set_membrane``)."""
    cloth.fabric = fabric
    scene.cloths.append(cloth)
    if max(fabric.bending) > 0:
        _join(scene, "bending", {"rigidity": fabric.bending})
    if not cloth.is_grid:
        _join(scene, "membrane", {"stretch": fabric.stretch, "shear": fabric.shear,
                                  "damping": fabric.damping})
    return cloth


def _join(scene, feature, values):
    """Add the scene's last cloth, at rest at its positions now, to the per-cloth
    feature ``feature`` (set_bending, set_membrane) with its values."""
    old, rest = getattr(scene, feature), scene.positions
    values = {key: [value] for key, value in values.items()}
    cloths = [len(scene.cloths) - 1]
    if old is not None:
        rest[:len(old["rest_positions"])] = old["rest_positions"]
        values = {key: list(old[key]) + value for key, value in values.items()}
        cloths = old["cloths"] + cloths
    getattr(scene, "set_" + feature)(**values, cloths=cloths, rest_positions=rest)


def add_rope(scene, start, end, segments, mass, stiffness, damping, pinned):
    """``Scene.add_rope``: a chain of particles and springs."""
    a, b = as_vec3("start", start), as_vec3("end", end)
    n = as_int("segments", segments, 1)
    if np.allclose(a, b, rtol=0, atol=0):
        raise SceneError(f"start and end must differ (both are {a.tolist()})")
    total = as_scalar("mass", mass, minimum=0.0, strict=True)
    ends = {"start": 0, "end": n}
    if isinstance(pinned, str) or any(p not in ends for p in pinned):
        raise SceneError(f"pinned must be a tuple of 'start' and/or 'end' (got {pinned!r})")
    pin = np.zeros(n + 1, dtype=bool)
    for p in pinned:
        pin[ends[p]] = True
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    ids = scene.add_particles(a + t * (b - a), mass=total / (n + 1), pinned=pin)
    sids = scene.add_springs(np.stack([ids[:-1], ids[1:]], 1), stiffness, damping,
                            kind="structural")
    rope = Rope(ids, sids)
    scene.ropes.append(rope)
    return rope
