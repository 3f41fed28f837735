"""The separating planes' normals (``guard.py``): for each candidate pair at a step's
start, the direction along which its two sides are kept apart, and the margin.

A plane normal to n keeps the pair apart along the whole motion if every vertex a of its
first side and b of its second keep n . (x_a - x_b) >= delta at the motion's end (the
guard's docstring). Any n along which the sides are separated at x0 will do; which one
decides what motion the plane allows. The closest points' direction is the obvious
choice, but between two layers it tilts toward the lateral offset of the closest
features: two cloths' grid edges lie parallel in pairs, offset across the layers, and a
plane normal to their closest points' direction stops one edge from passing over the
other, which a cloth sliding over another does at every step (``docs/contact.md``). The
surfaces' normal does not: a triangle's for a point, the summed vertex normals for two
edges. But it is no plane for every pair: in a twisting cloth a triangle turns, and a
plane along its normal asks a point far out on its side to keep clear of where the plane
sweeps, which the closest points' plane does not. Which of the two a pair's motion needs
is told by the motion, not by x0: ``normal_margin`` takes the surfaces' normal (where it
separates the pair by enough at x0) unless the motion's end x1 (a solver's prediction,
or its result for the guard) crosses its plane and keeps more room from the closest
points' plane. The choice is a branch, kept with the plane (``Planes.surface``) and with
each correction or cut a gradient reads (``SURFACE`` added to the kind), so the adjoints
differentiate the plane the forward step used (``chosen_margin``). The self-contact
projection's velocity pass (``terms/self_contact.py``) takes the surfaces' normal by the
same test of separation, without a motion (``contact_normal``).
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
SURFACE = 2              # a plane along the surfaces' normal: added to its kind in the logs
# where the motion crosses both planes, the surfaces' normal is taken where it leaves more
# room than the closest points' by this fraction of the thickness: where the two coincide
# (a point above a flat triangle's inside, crossing edges of two flat layers) rounding
# would choose, and the gradient's branch (``chosen_margin``) would not be the one
# central differences see
PREFER = 1e-3
# ``normal_margin``'s choice for a solver's predicted motion (``ContactStage.search_solve``):
# where the prediction crosses both planes (a layer landing on another), the surfaces'
# normal. A prediction is not the motion the solver ends with: the closest points' plane
# of a landing pair would turn the landing's correction into braking along the layers at
# every substep (XPBD's sliding cloth kept 0.41 of 1 m/s at 5 substeps)
PREDICTED = 2


@ti.func
def normal_margin(ids, kind, x0, x1, thickness, normals, choose: ti.template()):
    """(unit normal, D0, delta, SURFACE or 0) of a candidate at x0; D0 <= LEAST_GAP: no
    normal. The closest points' direction unless ``choose``; with it, the surfaces' normal
    (where it separates the pair by enough, ``surface_margin``) where the motion x0 -> x1
    does not cross its plane (``room`` >= 0) or crosses it less than the closest points'
    by PREFER thickness; with ``choose`` PREDICTED, also where the motion crosses both
    (comes within PREFER thickness of the closest points')."""
    n, d0, delta = closest_margin(ids, kind, x0, thickness)
    choice = 0
    if ti.static(choose):
        if d0 > LEAST_GAP:
            m, s, margin = surface_margin(ids, kind, x0, thickness, normals, n, d0)
            surface_room = room(ids, kind, x1, m, margin)
            closest_room = room(ids, kind, x1, n, delta)
            crossed = closest_room < PREFER * thickness
            if ti.static(choose != PREDICTED):
                crossed = surface_room > closest_room + PREFER * thickness
            if s > LEAST_GAP and (surface_room >= 0.0 or crossed):
                n, d0, delta, choice = m, s, margin, SURFACE
    return n, d0, delta, choice


@ti.func
def logged_kind(logged):
    """(kind, choice) of a kind as the logs keep it: plus SURFACE where the plane took the
    surfaces' normal (``chosen_margin``'s choice)."""
    kind = logged % SURFACE
    return kind, logged - kind


@ti.func
def chosen_margin(ids, kind, choice, x0, thickness, normals):
    """(unit normal, D0, delta) of a candidate at x0 along the normal ``normal_margin``
    chose (``choice``: its fourth value)."""
    n, d0, delta = closest_margin(ids, kind, x0, thickness)
    if choice == SURFACE:
        n, d0, delta = surface_margin(ids, kind, x0, thickness, normals, n, d0)
    return n, d0, delta


@ti.func
def closest_margin(ids, kind, x0, thickness):
    """(unit normal, D0, delta) along the closest points' direction at x0: D0 their
    distance, delta ``margin(D0)``."""
    alpha, g = gap(ids, kind, x0)
    d0 = g.norm()
    return g / ti.max(d0, LEAST_GAP), d0, margin(d0, thickness)


@ti.func
def surface_margin(ids, kind, x0, thickness, normals, n, d0):
    """(unit normal, D0, delta) along the surfaces' normal (``surface_normal``, on the
    side of the closest points' direction n, their distance d0): D0 the least separation
    of the vertex pairs along it, or 0 where that is below min(d0 / 2, 2 FLOOR
    thickness)."""
    p = corners(ids, x0)
    a, b = sides(ids, normals)
    m = surface_normal(kind, p, a, b, n)
    s = separation(kind, p, m)
    if s < ti.min(0.5 * d0, 2.0 * FLOOR * thickness):
        s = 0.0
    return m, s, margin(s, thickness)


@ti.func
def contact_normal(ids, kind, x, normals, g, thickness):
    """(unit normal, SURFACE or 0) of a contact law's correction at x with gap g: the
    surfaces' normal where it separates the contact by enough (``surface_margin``),
    else the closest points' direction. Between two layers the closest points'
    direction of offset features tilts along the layers, and a correction along it
    takes the sliding layer's speed."""
    d = g.norm()
    n = g / ti.max(d, 1e-30)
    choice = 0
    if d > LEAST_GAP:
        m, s, _ = surface_margin(ids, kind, x, thickness, normals, n, d)
        if s > LEAST_GAP:
            n, choice = m, SURFACE
    return n, choice


@ti.func
def corners(ids, x):
    """A candidate's four positions at x as the rows of a 4 x 3 matrix."""
    return ti.Matrix.rows([x[ids[0]], x[ids[1]], x[ids[2]], x[ids[3]]])


@ti.func
def sides(ids, normals):
    """(a, b): the vertex normals (``vertex_normals``) of a candidate's first two and
    last two particles, summed: an edge-edge contact's two edges'."""
    return normals[ids[0]] + normals[ids[1]], normals[ids[2]] + normals[ids[3]]


@ti.func
def _row(p, k: ti.template()):
    return ti.Vector([p[k, 0], p[k, 1], p[k, 2]])


@ti.func
def margin(d0, thickness):
    """delta of a plane that separates a pair by d0 at x0: pairs end a step at least
    min(d0 / 2, thickness) apart along it, and at least FLOOR thickness."""
    return ti.min(thickness, ti.max(0.5 * d0, FLOOR * thickness))


@ti.func
def room(ids, kind, x1, n, delta):
    """The least n . (x1_a - x1_b) - delta over a candidate's vertex pairs across its
    sides: how far the motion's end keeps clear of the plane (negative: it crosses)."""
    return separation(kind, corners(ids, x1), n) - delta


@ti.func
def surface_normal(kind, p, a, b, n):
    """The unit normal of the surfaces between a candidate's sides at its corners p
    (``corners``), on n's side (0 where it has none): a point-triangle contact's
    triangle's; an edge-edge contact's, a + b, its two edges' vertex normals
    (``sides``; b turned to agree with a)."""
    m = (_row(p, 2) - _row(p, 1)).cross(_row(p, 3) - _row(p, 1))
    if kind != POINT_TRIANGLE:
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
def separation(kind, p, m):
    """The least m . (p_a - p_b) over a candidate's vertex pairs across its sides, p its
    corners (``corners``)."""
    least = 1e30
    for a, b in ti.static(VERTEX_PAIRS):
        if spans(kind, a, b):
            least = ti.min(least, m.dot(_row(p, a) - _row(p, b)))
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
def plane_row(cl, pl, c):
    """Candidate row c of list cl with its plane (``guard.Planes`` pl): (ids, kind, the
    plane's normal n, its delta)."""
    return cl.ids[c], cl.kind[c], pl.n[c], pl.delta[c]


@ti.func
def kept_apart(kind, delta, a: ti.template(), b: ti.template()):
    """Whether a row's plane keeps its vertices a and b (a pair of VERTEX_PAIRS) apart: the
    plane is set (delta > 0) and they lie on its two sides (``spans``)."""
    return delta > 0.0 and spans(kind, a, b)


@ti.func
def spans(kind, a: ti.template(), b: ti.template()):
    """Whether vertices a and b (a pair of VERTEX_PAIRS) lie on the two sides of a contact
    of ``kind``: the point and a triangle's vertex, or a vertex of each edge."""
    return ti.select(kind == POINT_TRIANGLE, ti.static(int(a == 0)),
                     ti.static(int(b >= 2))) == 1
