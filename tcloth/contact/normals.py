"""The separating planes' normals (``guard.py``): for each candidate pair at a step's
start, the direction along which its two sides are kept apart, and the margin.

A plane normal to n keeps the pair apart along the whole motion if every vertex a of its
first side and b of its second keep n . (x_a - x_b) >= delta at the motion's end (the
guard's docstring). Any n along which the sides are separated at x0 will do; which one
decides what motion the plane allows. The closest points' direction is the obvious
choice, but between two layers it tilts toward the lateral offset of the closest
features: two cloths' grid edges lie parallel in pairs, offset across the layers, and a
plane normal to their closest points' direction stops one edge from passing over the
other, which a cloth sliding over another does at every step (``docs/contact.md``). So
the surface's normal is taken where it separates the pair by enough (``normal_margin``).
"""
import taichi as ti

from ..runtime import serial
from .candidates import gap
from .search import POINT_TRIANGLE

# the (first side, second side) vertex pairs of either kind of contact: a point-triangle
# contact's (0, 1), (0, 2), (0, 3); an edge-edge contact's (0, 2), (0, 3), (1, 2), (1, 3)
VERTEX_PAIRS = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3))
FLOOR = 0.25             # pairs end a step at least this fraction of the thickness apart
LEAST_GAP = 1e-6         # m: a pair closer than this at x0 has no normal (float32 rounds
                         # coordinates near 1 m to 6e-8 m)


@ti.func
def normal_margin(ids, kind, x0, thickness, normals):
    """(unit normal, D0, delta) of a candidate at x0; D0 <= LEAST_GAP: no normal. The
    normal is the surface's where it separates the candidate's vertex pairs by
    min(the closest points' gap / 2, 2 FLOOR thickness) or more (``surface_normal``),
    else the closest points' direction; D0 is the least separation along it."""
    alpha, g = gap(ids, kind, x0)
    d0 = g.norm()
    n = g / ti.max(d0, LEAST_GAP)
    if d0 > LEAST_GAP:
        m = surface_normal(ids, kind, x0, normals, n)
        s = separation(ids, kind, x0, m)
        if s >= ti.min(0.5 * d0, 2.0 * FLOOR * thickness):
            n, d0 = m, s
    return n, d0, ti.min(thickness, ti.max(0.5 * d0, FLOOR * thickness))


@ti.func
def surface_normal(ids, kind, x0, normals, n):
    """The unit normal of the surfaces between a candidate's sides, on n's side (0 where
    it has none): a point-triangle contact's triangle's; an edge-edge contact's, the
    sum of its four vertices' normals (``vertex_normals``; each edge's sum turned to
    agree with the other's). Two cloths' grid edges lie parallel in pairs, offset
    across the layers, and their closest points' direction tilts toward the offset: a
    plane normal to it stops one edge from passing over the other, which a cloth
    sliding over another does at every step (``docs/contact.md``)."""
    m = (x0[ids[2]] - x0[ids[1]]).cross(x0[ids[3]] - x0[ids[1]])
    if kind != POINT_TRIANGLE:
        a = normals[ids[0]] + normals[ids[1]]
        b = normals[ids[2]] + normals[ids[3]]
        turn = 1.0
        if a.dot(b) < 0.0:
            turn = -1.0
        m = a + turn * b
    size = m.norm()
    unit = ti.Vector.zero(float, 3)
    if size > 0.0:
        unit = m / size
        if unit.dot(n) < 0.0:
            unit = -unit
    return unit


@ti.func
def separation(ids, kind, x0, m):
    """The least m . (x_a - x_b) over a candidate's vertex pairs across its sides."""
    least = 1e30
    for a, b in ti.static(VERTEX_PAIRS):
        if spans(kind, a, b):
            least = ti.min(least, m.dot(x0[ids[a]] - x0[ids[b]]))
    return least


@ti.func
def vertex_normals(table, x, out):
    """out = each particle's sum of its cloth triangles' normals times twice their
    areas at x (0 off the cloths): two loops at a kernel's top level."""
    ti.loop_config(serialize=ti.static(serial(out)))
    for p in range(out.shape[0]):
        out[p] = ti.Vector.zero(float, 3)
    ti.loop_config(serialize=ti.static(serial(table.triangles)))
    for t in range(table.triangle_count):
        tri = table.triangles[t]
        c = (x[tri[1]] - x[tri[0]]).cross(x[tri[2]] - x[tri[0]])
        for k in ti.static(range(3)):
            out[tri[k]] += c


@ti.func
def spans(kind, a: ti.template(), b: ti.template()):
    """Whether vertices a and b (a pair of VERTEX_PAIRS) lie on the two sides of a contact
    of ``kind``: the point and a triangle's vertex, or a vertex of each edge."""
    return ti.select(kind == POINT_TRIANGLE, ti.static(int(a == 0)),
                     ti.static(int(b >= 2))) == 1
