"""Collider shapes: signed distance, outward normal and the renderer's ray hit, and the
``ColliderTable`` that holds a scene's colliders as a struct field with named members.

A shape is one entry of ``SHAPES``: its name (the scene's ``kind``), how a collider dict
packs into the ``extent`` vector, its signed distance and, for the renderer, its ray hit
and shading normal. Every loop over colliders goes through the table's groups (one per
shape the scene has, static for the kernels) and ``for_each_contact``, so that a new shape
is one entry here.
"""
from dataclasses import dataclass
from typing import Callable

import numpy as np
import taichi as ti

from . import raycast, runtime


@ti.func
def _centre(col, t):
    """The collider's centre (or plane point) at time t: it moves with constant velocity."""
    return col.center + t * col.velocity


@ti.func
def _sphere_distance(col, x, t):
    d = x - _centre(col, t)
    length = d.norm()
    n = ti.Vector([0.0, 1.0, 0.0])
    if length > 0.0:
        n = d / length
    return length - col.extent[0], n


@ti.func
def _plane_distance(col, x, t):
    return (x - _centre(col, t)).dot(col.extent), col.extent


@ti.func
def _box_distance(col, x, t):
    rot = col.rotation
    q = rot.transpose() @ (x - _centre(col, t))
    d = ti.abs(q) - col.extent
    outside = ti.max(d, 0.0)
    phi = 0.0
    nl = ti.Vector([0.0, 0.0, 0.0])
    if outside.norm() > 0.0:
        phi = outside.norm()
        nl = outside / phi * ti.math.sign(q)
    else:
        # inside: the nearest face is the axis of least penetration
        phi = d[_largest_axis(d)]
        nl = _face_normal(q, d)
    return phi, rot @ nl


@ti.func
def _largest_axis(d):
    axis = 0
    if d[1] > d[axis]:
        axis = 1
    if d[2] > d[axis]:
        axis = 2
    return axis


@ti.func
def _face_normal(q, d):
    """The local normal of the box face nearest q (d = |q| - half extents)."""
    axis = _largest_axis(d)
    nl = ti.Vector([0.0, 0.0, 0.0])
    nl[axis] = 1.0 if q[axis] >= 0.0 else -1.0
    return nl


# The ray hits take the ray's origin o and unit direction d in any precision and compute
# in the wider of it and the colliders' (the renderer's float32 rays, the contact stage's
# sweeps in the simulation's precision).
@ti.func
def _sphere_hit(col, o, d, t):
    return raycast.hit_sphere(o, d, _centre(col, t), col.extent[0])


@ti.func
def _plane_hit(col, o, d, t):
    n = col.extent
    dn = d.dot(n)
    hit = -1.0
    if dn < -1e-6:
        hit = (_centre(col, t) - o).dot(n) / dn
    return hit


@ti.func
def _box_hit(col, o, d, t):
    """Slab test in the box frame: entry t > 0, or -1 (a ray from inside does not hit)."""
    rot = col.rotation
    half = col.extent
    ol = rot.transpose() @ (o - _centre(col, t))
    dl = rot.transpose() @ d
    t_near, t_far = -1e30, 1e30
    for k in ti.static(range(3)):
        inv = 1.0 / dl[k] if abs(dl[k]) > 1e-12 else 1e30
        t0 = (-half[k] - ol[k]) * inv
        t1 = (half[k] - ol[k]) * inv
        t_near = ti.max(t_near, ti.min(t0, t1))
        t_far = ti.min(t_far, ti.max(t0, t1))
    return t_near if (t_near <= t_far and t_near > 0.0) else -1.0


@ti.func
def _sphere_normal(col, p, t):
    return (p - ti.cast(_centre(col, t), ti.f32)).normalized()


@ti.func
def _plane_normal(col, p, t):
    return ti.cast(col.extent, ti.f32)


@ti.func
def _box_normal(col, p, t):
    rot = ti.cast(col.rotation, ti.f32)
    q = rot.transpose() @ (p - ti.cast(_centre(col, t), ti.f32))
    return rot @ _face_normal(q, ti.abs(q) - ti.cast(col.extent, ti.f32))


@ti.func
def _cylinder_local(q, radius, half):
    """(phi, local outward normal) of a capped cylinder along local y: radius, half
    height; inside, the nearest of the side and the caps."""
    r = ti.sqrt(q[0] * q[0] + q[2] * q[2])
    radial = ti.Vector([1.0, 0.0, 0.0])
    if r > 0.0:
        radial = ti.Vector([q[0] / r, 0.0, q[2] / r])
    axial = ti.Vector([0.0, 1.0 if q[1] >= 0.0 else -1.0, 0.0])
    dr, dy = r - radius, ti.abs(q[1]) - half
    phi = 0.0
    n = radial
    if dr > 0.0 or dy > 0.0:
        a, b = ti.max(dr, 0.0), ti.max(dy, 0.0)
        phi = ti.sqrt(a * a + b * b)
        n = (a * radial + b * axial) / phi
    elif dy > dr:
        phi = dy
        n = axial
    else:
        phi = dr
    return phi, n


@ti.func
def _cylinder_distance(col, x, t):
    rot = col.rotation
    phi, nl = _cylinder_local(rot.transpose() @ (x - _centre(col, t)), col.extent[0],
                              col.extent[1])
    return phi, rot @ nl


@ti.func
def _cylinder_hit(col, o, d, t):
    """Entry of a ray into the capped cylinder (side or caps), or -1."""
    rot = col.rotation
    radius, half = col.extent[0], col.extent[1]
    ol = rot.transpose() @ (o - _centre(col, t))
    dl = rot.transpose() @ d
    best = 1e30
    a = dl[0] * dl[0] + dl[2] * dl[2]
    b = ol[0] * dl[0] + ol[2] * dl[2]
    c = ol[0] * ol[0] + ol[2] * ol[2] - radius * radius
    disc = b * b - a * c
    if a > 1e-12 and disc >= 0.0:
        side = (-b - ti.sqrt(disc)) / a
        if side > 0.0 and ti.abs(ol[1] + side * dl[1]) <= half:
            best = side
    if ti.abs(dl[1]) > 1e-12:
        for sign in ti.static((-1.0, 1.0)):
            cap = (sign * half - ol[1]) / dl[1]
            px, pz = ol[0] + cap * dl[0], ol[2] + cap * dl[2]
            if cap > 0.0 and px * px + pz * pz <= radius * radius:
                best = ti.min(best, cap)
    return best if best < 1e30 else -1.0


@ti.func
def _cylinder_normal(col, p, t):
    rot = ti.cast(col.rotation, ti.f32)
    q = rot.transpose() @ (p - ti.cast(_centre(col, t), ti.f32))
    _, nl = _cylinder_local(q, ti.cast(col.extent[0], ti.f32), ti.cast(col.extent[1], ti.f32))
    return rot @ nl


@dataclass(frozen=True)
class Shape:
    """One collider shape.

    name: the scene's ``kind``. extent: collider dict -> 3 numbers (radius | normal |
    half extents | radius, half height, 0). signed_distance(col, x, t) -> (phi, outward unit normal): ti.func.
    ray_hit(col, o, d, t) -> the ray's entry parameter or -1 (from outside; any precision:
    the renderer's and the contact stage's), normal(col, p, t) -> shading normal in
    float32 for the renderer. checkered: drawn with the ground's squares.
    """
    name: str
    extent: Callable
    signed_distance: Callable
    ray_hit: Callable
    normal: Callable
    checkered: bool = False


SHAPES = (
    Shape("sphere", lambda c: (c["radius"], 0.0, 0.0), _sphere_distance, _sphere_hit,
          _sphere_normal),
    Shape("plane", lambda c: c["normal"], _plane_distance, _plane_hit, _plane_normal,
          checkered=True),
    Shape("box", lambda c: c["half_extents"], _box_distance, _box_hit, _box_normal),
    Shape("cylinder", lambda c: (c["radius"], c["half_height"], 0.0), _cylinder_distance,
          _cylinder_hit, _cylinder_normal),
)
SHAPE_NAMES = tuple(s.name for s in SHAPES)


def collider_struct():
    """The Taichi struct of one collider, in the current precision."""
    real = runtime.real()
    vec3 = ti.types.vector(3, real)
    return ti.types.struct(center=vec3, velocity=vec3, extent=vec3,
                           rotation=ti.types.matrix(3, 3, real), thickness=real,
                           stiffness=real, damping=real, friction=real, stick_velocity=real)


@dataclass(frozen=True)
class Group:
    """The colliders of one shape: rows first .. first + count - 1 (static for kernels)."""
    shape: int
    first: int
    count: int


@ti.data_oriented
class ColliderTable:
    """A scene's colliders as a struct field (sorted by shape) and their groups.

    Attributes:
        data: shape (count,) of ``collider_struct()``: center / plane point (m), velocity
            (m/s), extent, rotation (box; identity otherwise), thickness (m), stiffness
            (N/m), damping (ratio of critical), friction (mu), stick_velocity (m/s).
        groups: tuple of ``Group``, one per shape the scene has.
        count: number of colliders; kinds: (count,) shape index per row (NumPy).
    """

    def __init__(self, colliders, off=()):
        for c in colliders:
            if c["kind"] not in SHAPE_NAMES:
                raise ValueError(f"unknown collider kind {c['kind']!r} (known: {SHAPE_NAMES})")
        # rows sorted by shape; rows[k] is the scene index of row k
        self.rows = sorted(range(len(colliders)),
                           key=lambda i: SHAPE_NAMES.index(colliders[i]["kind"]))
        self.count = len(self.rows)
        self.kinds = np.array([SHAPE_NAMES.index(colliders[i]["kind"]) for i in self.rows],
                              dtype=np.int32)
        self.groups = tuple(Group(s, int(np.searchsorted(self.kinds, s)),
                                  int((self.kinds == s).sum()))
                            for s in range(len(SHAPES)) if (self.kinds == s).any())
        self.data = collider_struct().field(shape=max(self.count, 1))
        self.upload(colliders, off)

    def upload(self, colliders, off=()):
        """Write the colliders' current values into ``data``; the colliders whose scene
        indices are in ``off`` get stiffness 0, which switches them off (no force, energy,
        friction or projection; a scene's collider always has stiffness > 0)."""
        if not self.count:
            return
        npr = runtime.numpy_real()
        ordered = [colliders[i] for i in self.rows]

        def column(fn):
            return np.array([fn(c) for c in ordered], dtype=npr)
        values = {"center": column(lambda c: c["center"]),
                  "velocity": column(lambda c: c["velocity"]),
                  "extent": column(lambda c: SHAPES[SHAPE_NAMES.index(c["kind"])].extent(c)),
                  "rotation": column(lambda c: c.get("rotation", np.eye(3))),
                  **{key: column(lambda c, k=key: c[k]) for key in
                     ("thickness", "stiffness", "damping", "friction", "stick_velocity")}}
        values["stiffness"][np.isin(self.rows, list(off))] = 0.0
        self.data.from_numpy(values)

    @ti.func
    def for_each_contact(self, x, p, t, body: ti.template(), zero, ctx):
        """The sum over this table's colliders c of ``body(col, c, x, p, phi, n, ctx)``,
        with (phi, n) the signed distance and outward normal of x[p] (read afresh for each
        collider, so that a body may move the particle); ``zero`` starts the sum."""
        acc = zero
        for g in ti.static(self.groups):
            for c in range(g.first, g.first + g.count):
                col = self.data[c]
                phi, n = SHAPES[g.shape].signed_distance(col, x[p], t)
                acc += body(col, c, x, p, phi, n, ctx)
        return acc
