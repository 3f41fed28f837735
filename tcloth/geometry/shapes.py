"""Collider shapes: each one entry of ``SHAPES`` that carries all tcloth knows of it.

A ``Shape`` gives its name (the scene's ``kind``), its builder's arguments and checks
(``Scene.add_<name>`` is made from them, and checkpoints store and restore a collider
through them), how a collider dict packs into the kernels' ``extent`` vector, its signed
distance, its ray hit and shading normal (renderer, contact sweeps), its lowest point (the
drawn ground) and its mesh (viewer). Every loop over colliders goes through
``collider_table.ColliderTable``'s groups (one per shape the scene has, static for the
kernels) and ``for_each_contact``, so that a new shape is one entry here.
"""
import inspect
from dataclasses import dataclass
from typing import Callable

import numpy as np
import taichi as ti

from . import primitives, raycast
from ..errors import SceneError
from ..validate import as_rotation, as_scalar, as_vec3


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


# The cylinder and the capsule lie along their local y axis: each gives (phi, local normal)
# of a local point (``_cylinder_local``, ``_capsule_local``), and these turn it into the
# shape's distance and shading normal, and its ray into the local frame.
@ti.func
def _axial_distance(local: ti.template(), col, x, t):
    rot = col.rotation
    phi, nl = local(rot.transpose() @ (x - _centre(col, t)), col.extent[0], col.extent[1])
    return phi, rot @ nl


@ti.func
def _axial_normal(local: ti.template(), col, p, t):
    rot = ti.cast(col.rotation, ti.f32)
    q = rot.transpose() @ (p - ti.cast(_centre(col, t), ti.f32))
    _, nl = local(q, ti.cast(col.extent[0], ti.f32), ti.cast(col.extent[1], ti.f32))
    return rot @ nl


@ti.func
def _axial_ray(col, o, d, t):
    """(origin, direction) of a ray in the collider's frame; (radius, half height)."""
    rot = col.rotation
    return (rot.transpose() @ (o - _centre(col, t)), rot.transpose() @ d, col.extent[0],
            col.extent[1])


@ti.func
def _side_entry(ol, dl, radius, half):
    """Entry of a local ray into the side of the cylinder of ``radius`` between y = -half
    and y = half, or 1e30."""
    best = 1e30
    a = dl[0] * dl[0] + dl[2] * dl[2]
    b = ol[0] * dl[0] + ol[2] * dl[2]
    c = ol[0] * ol[0] + ol[2] * ol[2] - radius * radius
    disc = b * b - a * c
    if a > 1e-12 and disc >= 0.0:
        side = (-b - ti.sqrt(disc)) / a
        if side > 0.0 and ti.abs(ol[1] + side * dl[1]) <= half:
            best = side
    return best


@ti.func
def _cylinder_distance(col, x, t):
    return _axial_distance(_cylinder_local, col, x, t)


@ti.func
def _cylinder_hit(col, o, d, t):
    """Entry of a ray into the capped cylinder (side or caps), or -1."""
    ol, dl, radius, half = _axial_ray(col, o, d, t)
    best = _side_entry(ol, dl, radius, half)
    if ti.abs(dl[1]) > 1e-12:
        for sign in ti.static((-1.0, 1.0)):
            cap = (sign * half - ol[1]) / dl[1]
            px, pz = ol[0] + cap * dl[0], ol[2] + cap * dl[2]
            if cap > 0.0 and px * px + pz * pz <= radius * radius:
                best = ti.min(best, cap)
    return best if best < 1e30 else -1.0


@ti.func
def _cylinder_normal(col, p, t):
    return _axial_normal(_cylinder_local, col, p, t)


@ti.func
def _capsule_local(q, radius, half):
    """(phi, local outward normal) of a capsule along local y: the segment |y| <= half
    thickened by radius."""
    d = q - ti.Vector([0.0, ti.min(ti.max(q[1], -half), half), 0.0])
    length = d.norm()
    n = ti.Vector([1.0, 0.0, 0.0])
    if length > 0.0:
        n = d / length
    return length - radius, n


@ti.func
def _capsule_distance(col, x, t):
    return _axial_distance(_capsule_local, col, x, t)


@ti.func
def _capsule_hit(col, o, d, t):
    """Entry of a ray into the capsule: the first of its entries into the side of the
    cylinder between the caps' centres and into the two spheres (a convex union), or -1."""
    ol, dl, radius, half = _axial_ray(col, o, d, t)
    best = _side_entry(ol, dl, radius, half)
    for sign in ti.static((-1.0, 1.0)):
        oc = ol - ti.Vector([0.0, sign * half, 0.0])
        bs = oc.dot(dl)
        ds = bs * bs - (oc.dot(oc) - radius * radius)
        if ds >= 0.0:
            entry = -bs - ti.sqrt(ds)
            if entry > 0.0:
                best = ti.min(best, entry)
    return best if best < 1e30 else -1.0


@ti.func
def _capsule_normal(col, p, t):
    return _axial_normal(_capsule_local, col, p, t)


REQUIRED = inspect.Parameter.empty


@dataclass(frozen=True)
class Parameter:
    """One shape argument of a collider builder (``Scene.add_<shape>``): its name, its
    check (name, value) -> the value stored (raises SceneError), its default (REQUIRED:
    none) and the collider dict's key for it (default: its name)."""
    name: str
    check: Callable
    default: object = REQUIRED
    key: str = None

    @property
    def stored(self):
        return self.key or self.name


def _positive(name, value):
    return as_scalar(name, value, minimum=0.0, strict=True)


def _unit(name, value):
    n = as_vec3(name, value)
    length = np.linalg.norm(n)
    if length < 1e-12:
        raise SceneError(f"{name} must be non-zero (got {n.tolist()})")
    return n / length


def _half_extents(name, value):
    h = as_vec3(name, value)
    if (h <= 0).any():
        raise SceneError(f"{name} must all be > 0 (got {h.tolist()})")
    return h


CENTER = Parameter("center", as_vec3)
ROTATION = Parameter("rotation", as_rotation, None)
# the arguments every collider builder takes after its shape's, with their defaults
COMMON = (("friction", 0.0), ("velocity", (0.0, 0.0, 0.0)), ("thickness", 0.005),
          ("stiffness", 1000.0), ("damping", 0.5), ("stick_velocity", 1e-3))


def _axis(c):
    """The collider's local y axis in the world (the columns of its rotation)."""
    return np.asarray(c.get("rotation", np.eye(3)), dtype=float)[:, 1]


def _turned(c, mesh):
    v, tris = mesh
    return v @ np.asarray(c["rotation"], dtype=float).T, tris, None


def _capsule_mesh(radius, half, rings=8, sectors=32):
    """Two hemispheres of ``radius`` whose centres are at y = +-half, and the band between."""
    theta = np.concatenate([np.linspace(0, np.pi / 2, rings + 1),
                            np.linspace(np.pi / 2, np.pi, rings + 1)])[:, None]
    v = radius * primitives.rings(theta, sectors)
    top = np.repeat(np.arange(len(theta)) <= rings, sectors + 1)
    v[:, 1] += np.where(top, half, -half)
    return v, primitives.grid_triangles(2 * rings + 1, sectors)


@dataclass(frozen=True)
class Shape:
    """One collider shape: everything about it that the rest of tcloth reads.

    name: the scene's ``kind`` (and ``Scene.add_<name>``). parameters: its own builder
    arguments (``Parameter``), before the ``COMMON`` ones. doc: the builder's docstring.
    extent: collider dict -> 3 numbers for the kernels (radius | normal | half extents |
    radius, half height, 0). signed_distance(col, x, t) -> (phi, outward unit normal):
    ti.func. ray_hit(col, o, d, t) -> the ray's entry parameter or -1 (from outside; any
    precision: the renderer's and the contact stage's). normal(col, p, t) -> shading
    normal in float32 for the renderer. bottom(c) -> its lowest height (m) at t = 0 (None:
    unbounded), to place the drawn ground. mesh(c, half, tile) -> (vertices about its
    centre, triangles, colours or None) for the viewer (a plane: a square of side 2 half
    in tiles of side ``tile``). checkered: drawn with the ground's squares.
    """
    name: str
    parameters: tuple
    doc: str
    extent: Callable
    signed_distance: Callable
    ray_hit: Callable
    normal: Callable
    bottom: Callable
    mesh: Callable
    checkered: bool = False
    meshed: bool = False


_OTHERS = "\n\n        Other arguments as for add_sphere.\n        "

SHAPES = (
    Shape("sphere", (CENTER, Parameter("radius", _positive)),
          """Add a sphere collider (see tcloth.terms.colliders for the contact model).

        Args:
            center: (3,) m at t = 0; it moves with constant ``velocity`` (3,) m/s.
            radius: m, > 0. friction: Coulomb mu >= 0.
            thickness: contact offset (m, default 5 mm): particles rest this far out.
            stiffness: penalty k (N/m, default 1000). damping: normal damping as a ratio
                of critical for each particle (default 0.5). stick_velocity: friction
                regularisation speed eps (m/s, default 1e-3).
        Returns:
            dict describing the collider.
        """,
          lambda c: (c["radius"], 0.0, 0.0), _sphere_distance, _sphere_hit, _sphere_normal,
          lambda c: float(c["center"][1] - c["radius"]),
          lambda c, half, tile: (*primitives.sphere(c["radius"]), None)),
    Shape("plane", (Parameter("point", as_vec3, (0.0, 0.0, 0.0), key="center"),
                    Parameter("normal", _unit, (0.0, 1.0, 0.0))),
          "Add an infinite plane through ``point`` whose solid side is opposite ``normal``."
          + _OTHERS,
          lambda c: c["normal"], _plane_distance, _plane_hit, _plane_normal,
          lambda c: None,
          lambda c, half, tile: primitives.tiles((0.0, 0.0, 0.0), c["normal"], half, tile),
          checkered=True),
    Shape("box", (CENTER, Parameter("half_extents", _half_extents), ROTATION),
          "Add a box: ``half_extents`` (3,) > 0 along its local axes, the columns of\n"
          "        ``rotation`` (a 3x3 rotation matrix; None = axis-aligned)." + _OTHERS,
          lambda c: c["half_extents"], _box_distance, _box_hit, _box_normal,
          lambda c: float(c["center"][1] - np.abs(np.asarray(c["rotation"])[1])
                          @ np.asarray(c["half_extents"])),
          lambda c, half, tile: _turned(c, primitives.box(np.asarray(c["half_extents"])))),
    Shape("cylinder", (CENTER, Parameter("radius", _positive),
                       Parameter("half_height", _positive), ROTATION),
          "Add a capped cylinder: ``radius`` and ``half_height`` (m, > 0) along its local\n"
          "        y axis, the second column of ``rotation`` (None: vertical), centred at "
          "``center``." + _OTHERS,
          lambda c: (c["radius"], c["half_height"], 0.0), _cylinder_distance, _cylinder_hit,
          _cylinder_normal,
          # its caps' rims reach radius * sqrt(1 - a_y^2) below the axis's end
          lambda c: float(c["center"][1] - abs(_axis(c)[1]) * c["half_height"]
                          - c["radius"] * np.sqrt(max(1.0 - _axis(c)[1] ** 2, 0.0))),
          lambda c, half, tile: _turned(c, primitives.cylinder(c["radius"],
                                                               c["half_height"]))),
    Shape("capsule", (CENTER, Parameter("radius", _positive),
                      Parameter("half_height", _positive), ROTATION),
          "Add a capsule: the points within ``radius`` (m, > 0) of the segment of\n"
          "        half length ``half_height`` (m, > 0) along its local y axis, the second\n"
          "        column of ``rotation`` (None: vertical), centred at ``center``." + _OTHERS,
          lambda c: (c["radius"], c["half_height"], 0.0), _capsule_distance, _capsule_hit,
          _capsule_normal,
          lambda c: float(c["center"][1] - abs(_axis(c)[1]) * c["half_height"] - c["radius"]),
          lambda c, half, tile: _turned(c, _capsule_mesh(c["radius"], c["half_height"]))),
    Shape("mesh", (), "A triangle mesh: Scene.add_mesh_collider.",
          lambda c: (c["reach"], 0.0, 0.0), None, None, None,
          lambda c: float((c["vertices"] @ np.asarray(c["rotation"]).T)[:, 1].min()
                          + c["center"][1]),
          lambda c, half, tile: (c["vertices"] @ np.asarray(c["rotation"], dtype=float).T,
                                 c["faces"], None),
          meshed=True),
)
SHAPE_NAMES = tuple(s.name for s in SHAPES)


def shape_of(collider):
    """The Shape of a scene collider dict."""
    return SHAPES[SHAPE_NAMES.index(collider["kind"])]


def collider_builder(shape):
    """``Scene.add_<shape.name>(scene, <shape's parameters>, <COMMON>)``: checks each
    argument and adds the collider through ``Scene.add_collider``."""
    signature = inspect.Signature(
        [inspect.Parameter("scene", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
        + [inspect.Parameter(p.name, inspect.Parameter.POSITIONAL_OR_KEYWORD, default=p.default)
           for p in shape.parameters]
        + [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default)
           for name, default in COMMON])

    def add(scene, *args, **kwargs):
        bound = signature.bind(scene, *args, **kwargs)
        bound.apply_defaults()
        given = bound.arguments
        return scene.add_collider(shape.name, {p.stored: p.check(p.name, given[p.name])
                                               for p in shape.parameters},
                                  **{name: given[name] for name, _ in COMMON})
    add.__signature__ = signature
    add.__name__ = add.__qualname__ = f"add_{shape.name}"
    add.__doc__ = shape.doc
    return add
