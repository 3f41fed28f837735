"""A scene's colliders as Taichi data: ``ColliderTable``, a struct field with named
members sorted by shape, and its groups (one per shape the scene has, static for the
kernels); the mesh colliders' geometry in a ``meshstore.MeshStore``, those that can be
signed distance fields baked in an ``sdf.SdfStore``, and their motion step by step
(``advance``)."""
import warnings
from dataclasses import dataclass

import numpy as np
import taichi as ti

from .. import runtime
from ..geometry.meshstore import MeshStore
from ..geometry.sdf import CERTIFIED, SdfStore
from ..geometry.shapes import SHAPE_NAMES, SHAPES, shape_of
from ..scene.meshcollider import step_pose, world_vertices


def collider_struct(meshes=True):
    """The Taichi struct of one collider, in the current precision; without ``meshes``
    it has no mesh index (its members are all real, so its field may carry gradients)."""
    real = runtime.real()
    vec3 = ti.types.vector(3, real)
    mesh = {"mesh": ti.i32} if meshes else {}
    return ti.types.struct(center=vec3, velocity=vec3, extent=vec3,
                           rotation=ti.types.matrix(3, 3, real), thickness=real,
                           stiffness=real, damping=real, friction=real, stick_velocity=real,
                           spin=vec3, **mesh)


@dataclass(frozen=True)
class Group:
    """The colliders of one shape: rows first .. first + count - 1 (static for kernels)."""
    shape: int
    first: int
    count: int


def _speed(c):
    """The fastest a scene collider's surface moves at the speeds it was given (m/s)."""
    speed = float(np.linalg.norm(c["velocity"]))
    if c["kind"] == "mesh":
        speed += float(np.linalg.norm(c["spin"])) * float(
            np.linalg.norm(c["vertices"], axis=1).max())
    return speed


@ti.data_oriented
class ColliderTable:
    """A scene's colliders as a struct field (sorted by shape) and their groups.

    Attributes:
        data: shape (count,) of ``collider_struct()``: center / plane point (m), velocity
            (m/s), extent, rotation (box, cylinder, capsule, mesh; identity otherwise),
            thickness (m), stiffness (N/m), damping (ratio of critical), friction (mu),
            stick_velocity (m/s), spin (a mesh's angular velocity, rad/s), mesh (its index
            in ``meshes``; absent from a differentiable table).
        groups: tuple of ``Group``, one per shape the scene has.
        count: number of colliders; kinds: (count,) shape index per row (NumPy).
        meshes: the mesh colliders' ``MeshStore`` (None without); moving: the rows whose
            pose or vertices ``advance`` sets each step (keyframed, deforming).
        sdf: the ``SdfStore`` of the mesh colliders (None without); fields: how many are
            distance fields; certified: the store's meshes on the certified pairs
            (``contact/obstacle.py``).

    differentiable: the table's ``data`` carries gradients (``tcloth.grad``); mesh colliders
    cannot be in it.
    """

    def __init__(self, colliders, off=(), differentiable=False):
        for c in colliders:
            if c["kind"] not in SHAPE_NAMES:
                raise ValueError(f"unknown collider kind {c['kind']!r} (known: {SHAPE_NAMES})")
            if differentiable and c["kind"] == "mesh":
                raise ValueError("a differentiable collider table cannot hold mesh colliders")
        # rows sorted by shape; rows[k] is the scene index of row k
        self.rows = sorted(range(len(colliders)),
                           key=lambda i: SHAPE_NAMES.index(colliders[i]["kind"]))
        self.count = len(self.rows)
        self.kinds = np.array([SHAPE_NAMES.index(colliders[i]["kind"]) for i in self.rows],
                              dtype=np.int32)
        self.groups = tuple(Group(s, int(np.searchsorted(self.kinds, s)),
                                  int((self.kinds == s).sum()))
                            for s in range(len(SHAPES)) if (self.kinds == s).any())
        self.data = collider_struct(not differentiable).field(shape=max(self.count, 1),
                                                              needs_grad=differentiable)
        meshed = [colliders[i] for i in self.rows if colliders[i]["kind"] == "mesh"]
        self.mesh_rows = [k for k, i in enumerate(self.rows) if colliders[i]["kind"] == "mesh"]
        self.meshes = MeshStore(meshed) if meshed else None
        self.mesh_colliders = meshed
        for m, c in enumerate(meshed):
            if c["closed"] and self.meshes.crossed(m):
                warnings.warn("a mesh collider crosses itself: it is taken as open "
                              "(two-sided)", stacklevel=4)
                self.meshes.open(m)
        self.sdf = SdfStore(self.meshes, meshed) if meshed else None
        self.fields = self.sdf.count if meshed else 0
        self.certified = [m for m, p in enumerate(self.sdf.paths if meshed else ())
                          if p["path"] == CERTIFIED]
        # (the fastest any collider's surface moves, m/s: a spinning mesh's rim; the
        # thickest collider, m): bounds for the solvers' reach at a step's start
        self.bounds = ti.field(runtime.real(), shape=2)
        self.moving = [(k, m, colliders[self.rows[k]]) for m, k in enumerate(self.mesh_rows)
                       if colliders[self.rows[k]]["keyframes"] is not None
                       or colliders[self.rows[k]]["deform"] is not None]
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
                  "extent": column(lambda c: shape_of(c).extent(c)),
                  "rotation": column(lambda c: c.get("rotation", np.eye(3))),
                  "spin": column(lambda c: c.get("spin", np.zeros(3))),
                  **{key: column(lambda c, k=key: c[k]) for key in
                     ("thickness", "stiffness", "damping", "friction", "stick_velocity")}}
        values["stiffness"][np.isin(self.rows, list(off))] = 0.0
        self.bounds.from_numpy(np.array([max(_speed(c) for c in ordered), max(
            c["thickness"] for c in ordered)], dtype=npr))
        if "mesh" in self.data.keys:
            values["mesh"] = np.zeros(self.count, np.int32)
            values["mesh"][self.mesh_rows] = np.arange(len(self.mesh_rows))
        self.data.from_numpy(values)
        self._step = None

    def advance(self, t0, dt):
        """The keyframed and deforming mesh colliders over the step from t0 to t0 + dt: a
        keyframed one's row moves it from its pose at t0 to its pose at t0 + dt, a
        deforming one's vertices at both ends go to the store."""
        if not self.moving or self._step == (t0, dt):
            return
        self._step = (t0, dt)
        for k, m, c in self.moving:
            if c["keyframes"] is not None:
                center, velocity, rotation, spin = step_pose(c, t0, dt)
                for name, value in (("center", center), ("velocity", velocity),
                                    ("rotation", rotation), ("spin", spin)):
                    getattr(self.data, name)[k] = value
            else:
                self.meshes.set_frames(m, t0, t0 + dt, world_vertices(c, t0),
                                       world_vertices(c, t0 + dt))

    @ti.func
    def contact(self, shape: ti.template(), col, x, t, beyond=-1.0, far: ti.template() = False):
        """(phi, outward normal, the surface's velocity there) of x against collider row
        ``col`` of shape index ``shape`` at time t. ``beyond`` >= 0: only phi below the
        collider's thickness plus that much is needed (a mesh searches no farther and
        answers that bound for points beyond it). A mesh field answers from its band, and
        beyond it its band (a lower bound); with ``far`` (a caller whose ``beyond`` can
        reach past the band: the solvers' planes) the exact mesh answers there, counted
        in ``sdf.fallbacks`` where it finds the surface within reach."""
        phi, n, u = 0.0, ti.Vector.zero(float, 3), col.velocity
        if ti.static(SHAPES[shape].meshed):
            reach = col.extent[0]
            if beyond >= 0.0:
                reach = ti.min(reach, col.thickness + beyond)
            exact = True
            if ti.static(self.fields > 0):
                k = self.sdf.of_mesh[col.mesh]
                if k >= 0:
                    inside = False
                    phi, n, u, inside = self.sdf.contact(col, k, x, t)
                    exact = False
                    if ti.static(far):
                        exact = not inside and reach > self.sdf.band[k]
            if ti.static(far or self.fields < len(self.mesh_rows)):
                if exact:
                    phi, n, u = self.meshes.contact(col, x, t, reach)
                    if ti.static(far and self.fields > 0):
                        if phi < reach and self.sdf.of_mesh[col.mesh] >= 0:
                            ti.atomic_add(self.sdf.fallbacks[None], 1)
        else:
            phi, n = SHAPES[shape].signed_distance(col, x, t)
        return phi, n, u

    @ti.func
    def distance(self, shape: ti.template(), col, x, t):
        """(phi, outward normal) of x against collider row ``col`` at time t."""
        phi, n, _ = self.contact(shape, col, x, t)
        return phi, n

    @ti.func
    def ray_hit(self, shape: ti.template(), col, o, d, t):
        """The shape's ray hit (``shapes.Shape.ray_hit``)."""
        hit = 0.0
        if ti.static(SHAPES[shape].meshed):
            hit = self.meshes.ray_hit(col, o, d, t)
        else:
            hit = SHAPES[shape].ray_hit(col, o, d, t)
        return hit

    @ti.func
    def normal(self, shape: ti.template(), col, p, t):
        """The shape's shading normal (``shapes.Shape.normal``)."""
        n = ti.Vector.zero(ti.f32, 3)
        if ti.static(SHAPES[shape].meshed):
            n = self.meshes.normal(col, p, t)
        else:
            n = SHAPES[shape].normal(col, p, t)
        return n

    @ti.func
    def for_each_contact(self, x, p, t, body: ti.template(), zero, ctx, beyond=-1.0,
                         far: ti.template() = False):
        """The sum over this table's colliders c of ``body(col, c, x, p, phi, n, ctx)``,
        with (phi, n) the signed distance and outward normal of x[p] (read afresh for each
        collider, so that a body may move the particle) and ``col.velocity`` the
        surface's velocity at the closest point (a turning or deforming mesh's own);
        ``zero`` starts the sum; ``beyond`` and ``far``: as ``contact``'s (bodies then see
        phi no larger than the thickness plus ``beyond``, or than a field's band)."""
        acc = zero
        for g in ti.static(self.groups):
            for c in range(g.first, g.first + g.count):
                col = self.data[c]
                phi, n, u = self.contact(g.shape, col, x[p], t, beyond, far)
                col.velocity = u
                acc += body(col, c, x, p, phi, n, ctx)
        return acc
