"""Ray-primitive intersections and the depth keys of the renderer.

A hit is one int64 key, the hit distance's float32 bits above the primitive id (positive
floats order like their bits): ``atomic_min`` of keys keeps the nearest hit, ties going to
the smaller id, whatever the order of the threads.
"""
import taichi as ti


@ti.func
def hit_triangle(o, d, a, b, c):
    """Moller-Trumbore: (t, u, v) with t < 0 when the ray misses."""
    e1, e2 = b - a, c - a
    pv = d.cross(e2)
    det = e1.dot(pv)
    result = ti.Vector([-1.0, 0.0, 0.0], ti.f32)
    if abs(det) > 1e-12:
        inv = 1.0 / det
        tv = o - a
        u = tv.dot(pv) * inv
        qv = tv.cross(e1)
        v = d.dot(qv) * inv
        if u >= 0.0 and v >= 0.0 and u + v <= 1.0:
            result = ti.Vector([e2.dot(qv) * inv, u, v], ti.f32)
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
