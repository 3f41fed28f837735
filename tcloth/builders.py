"""Builders: Provot cloth grids and ropes, added to a Scene as particles and springs."""
import numpy as np

from .errors import SceneError
from .validate import (as_int, as_rotation, as_scalar, as_spring_params, as_vec3, fmt)


class Cloth:
    """A Provot cloth on a regular grid, as added by ``Scene.add_cloth``.

    Attributes:
        particles: (ny, nx) int array of particle ids; row j, column i.
        triangles: (T, 3) int array of particle ids, counter-clockwise seen from the front.
        springs: dict family -> (M_family,) int array of spring ids.
        resolution: (nx, ny); spacing: (dx, dy) in metres; offset: id of particle (0, 0).
        params: dict family -> (k_s, k_d) or None.
    """

    def __init__(self, offset, resolution, spacing, params, plane):
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


class Rope:
    """A chain of particles joined by springs, as added by ``Scene.add_rope``.

    Attributes: particles (segments+1,) ids from start to end; springs (segments,) ids.
    """

    def __init__(self, particles, springs):
        self.particles = particles
        self.springs = springs


def add_cloth(scene, resolution, size, center, plane, mass, structural, shear, flexion,
              pinned, rotation=None):
    """``Scene.add_cloth``: the particles and springs of a Provot cloth grid."""
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
    total = as_scalar("mass", mass, minimum=0.0, strict=True)
    params = {"structural": as_spring_params("structural", structural),
              "shear": as_spring_params("shear", shear),
              "flexion": as_spring_params("flexion", flexion)}
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
    cloth = Cloth(scene.num_particles, (nx, ny), (dx, dy), params, plane)
    pos = pos.reshape(-1, 3)
    if rotation is not None:
        pos = pos @ as_rotation("rotation", rotation).T
    scene.add_particles(pos + c, mass=total / (nx * ny), pinned=pin.ravel())
    for family, kskd in params.items():
        pairs = cloth.grid_pairs(family)
        if kskd is None or len(pairs) == 0:
            cloth.springs[family] = np.zeros(0, dtype=np.int64)
            continue
        cloth.springs[family] = scene.add_springs(pairs, kskd[0], kskd[1], kind=family)
    scene.cloths.append(cloth)
    return cloth


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
