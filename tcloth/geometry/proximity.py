"""Closest points between a point and a triangle and between two segments (ti.funcs).

Both return weights so that the gap vector between the two closest points is a weighted
sum of the primitives' vertices, sum_k alpha_k x_k (``contact_weights``): the distance's
gradient with respect to x_k is then alpha_k times the unit gap (the weights are those of
the minimising points, so their own change does not enter).
"""
import taichi as ti


@ti.func
def triangle_weights(p, a, b, c):
    """Barycentric weights (wa, wb, wc) of the point of triangle abc closest to p, by the
    Voronoi regions of its vertices, edges and face (Ericson, Real-Time Collision
    Detection, 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab.dot(ap), ac.dot(ap)
    bp = p - b
    d3, d4 = ab.dot(bp), ac.dot(bp)
    cp = p - c
    d5, d6 = ab.dot(cp), ac.dot(cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    w = ti.Vector([0.0, 0.0, 0.0])
    if d1 <= 0.0 and d2 <= 0.0:
        w = ti.Vector([1.0, 0.0, 0.0])
    elif d3 >= 0.0 and d4 <= d3:
        w = ti.Vector([0.0, 1.0, 0.0])
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        s = d1 / (d1 - d3)
        w = ti.Vector([1.0 - s, s, 0.0])
    elif d6 >= 0.0 and d5 <= d6:
        w = ti.Vector([0.0, 0.0, 1.0])
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        s = d2 / (d2 - d6)
        w = ti.Vector([1.0 - s, 0.0, s])
    elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        s = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        w = ti.Vector([0.0, 1.0 - s, s])
    else:
        inv = 1.0 / ti.max(va + vb + vc, 1e-30)
        v, u = vb * inv, vc * inv
        w = ti.Vector([1.0 - v - u, v, u])
    return w


@ti.func
def segment_parameters(p0, p1, q0, q1):
    """(s, u) in [0, 1]^2 of the closest points p0 + s (p1 - p0) and q0 + u (q1 - q0) of
    two segments of non-zero length (Ericson 5.1.9; parallel segments: s = 0)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1.dot(d1), d2.dot(d2), d2.dot(r)
    c, b = d1.dot(r), d1.dot(d2)
    denom = a * e - b * b
    s = 0.0
    if denom > 1e-6 * a * e:
        s = ti.math.clamp((b * f - c * e) / denom, 0.0, 1.0)
    u = (b * s + f) / e
    if u < 0.0:
        u = 0.0
        s = ti.math.clamp(-c / a, 0.0, 1.0)
    elif u > 1.0:
        u = 1.0
        s = ti.math.clamp((b - c) / a, 0.0, 1.0)
    return s, u


@ti.func
def contact_weights(kind, x0, x1, x2, x3):
    """alpha (4,) with gap = sum_k alpha_k x_k from the second side's closest point to the
    first's: kind 0 is point x0 against triangle (x1, x2, x3), kind 1 is segment (x0, x1)
    against segment (x2, x3)."""
    alpha = ti.Vector([0.0, 0.0, 0.0, 0.0])
    if kind == 0:
        w = triangle_weights(x0, x1, x2, x3)
        alpha = ti.Vector([1.0, -w[0], -w[1], -w[2]])
    else:
        s, u = segment_parameters(x0, x1, x2, x3)
        alpha = ti.Vector([1.0 - s, s, u - 1.0, -u])
    return alpha
