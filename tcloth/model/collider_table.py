"""A scene's colliders as Taichi data: ``ColliderTable``, a struct field with named
members sorted by shape, and its groups (one per shape the scene has, static for the
kernels)."""
from dataclasses import dataclass

import numpy as np
import taichi as ti

from .. import runtime
from ..geometry.shapes import SHAPE_NAMES, SHAPES, shape_of


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
                  "extent": column(lambda c: shape_of(c).extent(c)),
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
