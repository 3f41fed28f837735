"""Ray-primitive intersections and the depth keys of the renderer.

A hit is one int64 key, the hit distance's float32 bits above the primitive id (positive
floats order like their bits): ``atomic_min`` of keys keeps the nearest hit, ties going to
the smaller id, whatever the order of the threads.
"""
import taichi as ti


@ti.func
def plane_hit(o, d, a, b, c):
    """Moller-Trumbore without the inside test: (t, u, v) of the point a + u (b - a) +
    v (c - a) where the ray o + t d meets the triangle's plane; (-1, -1, -1) where the ray
    runs along it."""
    e1, e2 = b - a, c - a
    pv = d.cross(e2)
    det = e1.dot(pv)
    result = ti.Vector([-1.0, -1.0, -1.0])
    if abs(det) > 1e-12:
        inv = 1.0 / det
        tv = o - a
        qv = tv.cross(e1)
        result = ti.Vector([e2.dot(qv) * inv, tv.dot(pv) * inv, d.dot(qv) * inv])
    return result


@ti.func
def hit_triangle(o, d, a, b, c):
    """Moller-Trumbore: (t, u, v) with t < 0 when the ray misses."""
    h = plane_hit(o, d, a, b, c)
    result = ti.Vector([-1.0, 0.0, 0.0], ti.f32)
    if h[1] >= 0.0 and h[2] >= 0.0 and h[1] + h[2] <= 1.0:
        result = ti.cast(h, ti.f32)
    return result


@ti.func
def hit_sphere(o, d, centre, radius):
    """Nearest positive t of the ray on the sphere, or -1."""
    oc = o - centre
    b = oc.dot(d)
    disc = b * b - (oc.dot(oc) - radius * radius)
    t = -1.0
    if disc >= 0.0:
        s = ti.sqrt(disc)
        t = -b - s
        if t <= 0.0:
            t = -b + s
    return t


@ti.func
def key(t, prim_id):
    """int64 key ordering hits by distance t > 0, then by id."""
    return (ti.cast(ti.bit_cast(ti.cast(t, ti.f32), ti.i32), ti.i64) << 32) | ti.cast(prim_id, ti.i64)


@ti.func
def key_t(key):
    return ti.bit_cast(ti.cast(key >> 32, ti.i32), ti.f32)


@ti.func
def key_id(key):
    return ti.cast(key & 0x7FFFFFFF, ti.i32)
