"""The guarantee: a step's motion never takes cloth through cloth or a particle into a
collider, whatever the integrator and the step size (``docs/contact.md``).

The motion of a step is the straight path of every particle from its start x0 to its end
x1. Kernels here change x1 (and v1 by the same change over dt) until that motion is safe:

  - ``projection.project``: each candidate pair (a point and a triangle, or two edges) was
    separated at x0 by D0 > 0 along a unit normal n (``normals.py``: the surfaces'
    normal where it separates the pair by enough and the motion keeps clear of its
    plane, else its closest points' direction; D0 the least separation along it). The
    pair stays separated by the plane normal to n along the whole motion if, at x1, every
    vertex a of its first side and b of its second keep n . (x_a - x_b) >= delta: the
    function min_a n . x_a - max_b n . x_b is concave, so on the path it stays above its
    smaller end value. delta = min(thickness, max(D0 / 2, thickness / 4)): a pair may
    close to the thickness in one step, or halve a gap already inside it, never more, and
    one closer than a quarter of the thickness ends the step that far apart (float32
    resolves no gap of a few ulps of the coordinates). Violated vertex pairs are
    moved apart along n in proportion to their inverse masses (Gauss-Seidel sweeps over
    the candidates on CPUs; on GPUs Jacobi passes, all at once, each correction scaled
    by 1 / the larger of its two vertices' corrections in the pass, the same on both),
    and their approaching normal velocity is removed by an impulse
    along the same directions (inelastic: a move is not turned into a velocity, which
    at a small dt would add |move| / dt, so the guard adds no energy at any dt): each
    correction moves equal and opposite momenta, except where a
    collider stopped one of the two this step and the correction would move it into the
    collider: then that one moves only along the collider's surface (not at all where
    that would take it far for little), and the collider takes the rest of the
    reaction.
  - ``sweep_colliders``: a particle's path (relative to a moving collider) that enters a
    collider ends where it came within the collider's thickness (a ray cast, so a thin
    box cannot be stepped over; from a start already within the thickness, at the start:
    a stop leaves no more contact energy than the path began with, so it adds none), its
    normal velocity into the collider removed; one that started
    inside (by rounding, or a scene that started so) and would end deeper stays where it
    was relative to the collider (pushed out along the surface's normal at its end, it
    would go round the collider's edges, off its path, through cloth the pairs' guard
    has cleared).
  - ``truncate`` (the fail-safe, where the sweeps left violations): every vertex of every
    candidate pair is kept on its side of a plane normal to n between the pair's two
    sides at x0, placed by how fast each side approaches (planar Divide and Truncate,
    SIGGRAPH 2026), by cutting its displacement short: x1 = x0 + t (x1 - x0), t the
    smallest over its planes of 0.9 of the fraction that reaches the plane, and its
    velocity scaled by the same t (no energy added). A vertex on its side of a plane at
    both ends of its path is on it all along, so every pair stays separated whatever the
    others' cuts. It conserves no momentum; the stage counts it.
Pairs with no gap at x0 (touching, or a scene that started crossed) have no normal: they
are left as they are.
"""
import taichi as ti

from .. import runtime
from ..runtime import jacobi_apply, jacobi_zero, serial
from ..geometry.shapes import SHAPES
from .broad import near
from .field_sweep import field_paths
from .normals import (LEAST_GAP, VERTEX_PAIRS, kept_apart, normal_margin, plane_row, room,
                      spans, vertex_normals)
from .search import POINT_TRIANGLE

SLACK = 1e-3             # a violation below this fraction of delta is no violation
KEEP = 0.9               # the fail-safe stops a vertex at this fraction of its way to a plane
BACK_OFF = 1e-6          # m: a path a collider stops ends this far before the surface
# halvings of the stop's search along a path: to float64's last bit, so the stop is the
# root to rounding, on its outer side (a smooth function of the path, whose derivative
# the gradient takes: ``tcloth/grad/sweep.py``)
STOP_BISECTIONS = 53
FAR_APART = -1.0         # the delta of a candidate that cannot come within reach
PATH, START = 1, 2       # the kinds of a collider sweep's cut (``SweepLog``)


@ti.func
def _worst(ids, a: ti.template(), b: ti.template(), n, delta, x1):
    return delta - n.dot(x1[ids[a]] - x1[ids[b]])


@ti.func
def relative_path(ids, kind, x0, x1):
    """The longest relative displacement from x0 to x1 of a vertex pair across a
    candidate's sides: along straight paths its gap closes by at most that much."""
    most = 0.0
    for a, b in ti.static(VERTEX_PAIRS):
        if spans(kind, a, b):
            most = ti.max(most,
                          ((x1[ids[a]] - x0[ids[a]]) - (x1[ids[b]] - x0[ids[b]])).norm())
    return most


@ti.data_oriented
class Planes:
    """The guard's columns for the rows of one candidate list (``capacity`` rows): each
    row's separating plane at a step's start (``planes``: unit normal ``n``, ``delta``)
    and the vertex pairs the projection's Jacobi passes moved (``touched``,
    ``projection.py``). The stage keeps one beside each of its lists."""

    def __init__(self, capacity):
        real = runtime.real()
        self.capacity = capacity
        self.n = ti.Vector.field(3, real, shape=capacity)
        self.delta = ti.field(real, shape=capacity)
        # SURFACE where the plane took the surfaces' normal, else 0 (``normals.py``)
        self.surface = ti.field(ti.i32, shape=capacity)
        self.touched = ti.field(ti.i32, shape=capacity)


@ti.kernel
def planes(cl: ti.template(), pl: ti.template(), count: ti.i32, x0: ti.template(),
           x1: ti.template(), thickness: float, reach: float, choose: ti.template()):
    """Each candidate's unit normal and delta at the step's start x0 into ``pl.n`` and
    ``pl.delta`` (a ``Planes``), for ``project``, ``violations`` and ``truncate`` (the closest
    points cost more than the sweeps' checks). delta is 0 where it has no normal, and
    FAR_APART where its gap at x0 less the longest relative displacement of its vertex
    pairs from x0 to x1 stays above ``reach``: the gap of a point and a triangle (of
    two edges) is the length of a convex combination of those pairs' differences, so it
    cannot close by more on the motion, and such a pair stays farther apart than
    ``reach`` all along (the projection skips it; the fail-safe, whose cuts change the
    motion, does not). The normal is the one the motion x1 needs
    (``normals.normal_margin``; choose: True, or ``normals.PREDICTED`` where x1 is a
    solver's prediction)."""
    vertex_normals(cl.table, x0, cl.table.normals)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        _plane(cl, pl, c, x0, x1, thickness, reach, choose)


@ti.kernel
def near_planes(cl: ti.template(), pl: ti.template(), count: ti.i32, x0: ti.template(),
                x1: ti.template(), thickness: float, ref_gap: ti.template(),
                far: ti.template()):
    """``planes`` of the proximity list (``broad.BroadPhase``: ``ref_gap``) for a motion
    it covers (``far`` from its ``moved(x0, x1)``), with reach = thickness; a row that
    the list's bound keeps beyond the thickness all along (``broad.near``) is FAR_APART
    without its closest points, and without its normal, which the fail-safe's cuts need
    (``planes`` them again first). These planes only find the steps with something to
    correct: each takes the closest points' direction (no vertex normals, which would
    cost a pass over the triangles at every explicit substep). A motion that keeps clear
    of them is safe, as of any separating planes; where one is crossed, the guard makes
    the planes again (``planes``) before it corrects."""
    near_plane_rows(cl, pl, count, x0, x1, thickness, ref_gap, far)


@ti.func
def near_plane_rows(cl, pl, count, x0, x1, thickness, ref_gap, far):
    """``near_planes`` as a ``ti.func`` (a batch of substeps')."""
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        if near(cl, ref_gap, far, c, thickness):
            _plane(cl, pl, c, x0, x1, thickness, thickness, False)
        else:
            pl.delta[c] = FAR_APART


@ti.func
def _plane(cl, pl, c, x0, x1, thickness, reach, choose: ti.template()):
    """``planes``' row c; the closest points' direction unless ``choose``."""
    ids, kind = cl.ids[c], cl.kind[c]
    n, d0, delta, choice = normal_margin(ids, kind, x0, x1, thickness, cl.table.normals,
                                         choose)
    closing = relative_path(ids, kind, x0, x1)
    pl.n[c] = n
    pl.surface[c] = choice
    pl.delta[c] = 0.0
    if d0 > LEAST_GAP:
        pl.delta[c] = delta if d0 - closing <= reach else FAR_APART


@ti.kernel
def choose_again(cl: ti.template(), pl: ti.template(), count: ti.i32, x0: ti.template(),
                 x: ti.template(), thickness: float):
    """The planes (``planes``, every row kept) of the rows that x crosses chosen again for
    the motion x0 -> x (``normals.normal_margin``)."""
    vertex_normals(cl.table, x0, cl.table.normals)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        delta = pl.delta[c]
        if delta > 0.0 and room(cl.ids[c], cl.kind[c], x, pl.n[c], delta) < -SLACK * delta:
            _plane(cl, pl, c, x0, x, thickness, 1e30, True)


@ti.func
def _separate(ids, a: ti.template(), b: ti.template(), n, delta, x, inv_mass, dx, hits):
    """``_correct``'s move of vertices a and b, summed into dx and counted in hits
    instead of applied (a Jacobi pass); 1 if they were closer than delta, else 0."""
    pa, pb = ids[a], ids[b]
    violation = delta - n.dot(x[pa] - x[pb])
    w = inv_mass[pa] + inv_mass[pb]
    closer = 0
    if violation > SLACK * delta and w > 0.0:
        lam = violation / w
        dx[pa] += inv_mass[pa] * lam * n
        dx[pb] -= inv_mass[pb] * lam * n
        hits[pa] += 1
        hits[pb] += 1
        closer = 1
    return closer


@ti.kernel
def keep_apart(cl: ti.template(), pl: ti.template(), count: ti.i32, x: ti.template(),
               inv_mass: ti.template(), dx: ti.template(), hits: ti.template()) -> ti.i32:
    """One pass of the candidates' planes (``planes``) inside a solver's iterations: every
    vertex pair closer along its normal than delta is moved apart as
    ``projection.project`` moves it, all pairs at once (Jacobi, in parallel), each vertex
    by the mean of its moves. Returns how many vertex pairs were closer."""
    jacobi_zero(dx, hits)
    closer = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, kind, n, delta = plane_row(cl, pl, c)
        for a, b in ti.static(VERTEX_PAIRS):
            if kept_apart(kind, delta, a, b):
                closer += _separate(ids, a, b, n, delta, x, inv_mass, dx, hits)
    jacobi_apply(x, dx, hits)
    return closer


@ti.kernel
def violations(cl: ti.template(), pl: ti.template(), count: ti.i32,
               x1: ti.template()) -> ti.i32:
    """How many candidates have a vertex pair closer along their normal than delta
    (their ``planes``)."""
    return violated_rows(cl, pl, count, x1)


@ti.func
def violated_rows(cl, pl, count, x1):
    """``violations`` as a ``ti.func`` (a batch of substeps')."""
    bad = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, kind, n, delta = plane_row(cl, pl, c)
        if delta > 0.0:
            worst = 0.0
            for a, b in ti.static(VERTEX_PAIRS):
                if spans(kind, a, b):
                    worst = ti.max(worst, _worst(ids, a, b, n, delta, x1))
            if worst > SLACK * delta:
                bad += 1
    return bad


@ti.func
def dividing_plane(ids, kind, n, x0, x1):
    """(whether a plane normal to n divides the candidate's two sides at x0, its offset,
    the size of the first side): between the sides' extents along n at x0, placed by how
    fast each side approaches the other from x0 to x1."""
    first = 1 if kind == POINT_TRIANGLE else 2
    low_a, high_b = 1e30, -1e30
    a_speed, b_speed = 0.0, 0.0
    for k in ti.static(range(4)):
        along = n.dot(x0[ids[k]])
        if k < first:
            low_a = ti.min(low_a, along)
            a_speed = ti.max(a_speed, -n.dot(x1[ids[k]] - x0[ids[k]]))
        else:
            high_b = ti.max(high_b, along)
            b_speed = ti.max(b_speed, n.dot(x1[ids[k]] - x0[ids[k]]))
    divided = low_a - high_b > LEAST_GAP
    plane = 0.0
    if divided:
        share = 0.5
        if a_speed + b_speed > 0.0:
            share = ti.math.clamp(b_speed / (a_speed + b_speed), 0.05, 0.95)
        plane = high_b + share * (low_a - high_b)
    return divided, plane, first


@ti.func
def stop_fraction(x0, x1, n, plane, side, p):
    """The fraction of its path at which vertex p (on ``side`` = +1 or -1 of the plane
    n . y = plane) stops, KEEP of its way to the plane; 1 where it does not come that
    near."""
    start = side * (n.dot(x0[p]) - plane)
    approach = -side * n.dot(x1[p] - x0[p])
    t = 1.0
    if approach > (1.0 - KEEP) * start:
        t = KEEP * start / approach
    return t


@ti.kernel
def truncate(cl: ti.template(), pl: ti.template(), count: ti.i32, x0: ti.template(),
             x1: ti.template(), v1: ti.template(), inv_mass: ti.template(),
             t_out: ti.template(), log: ti.template()) -> ti.i32:
    """The fail-safe (module docstring): every vertex kept on its side of the dividing
    plane of every candidate with a normal (``planes``); where ``log`` (a
    ``TruncationLog``) is on, each cut vertex's plane kept. Returns how many vertices
    were cut short."""
    ti.loop_config(serialize=ti.static(serial(x1)))
    for p in range(x1.shape[0]):
        t_out[p] = 1.0
        log.claimed[p] = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, kind = cl.ids[c], cl.kind[c]
        if pl.delta[c] != 0.0:
            n = pl.n[c]
            divided, plane, first = dividing_plane(ids, kind, n, x0, x1)
            if divided:
                for k in ti.static(range(4)):
                    if inv_mass[ids[k]] > 0.0:
                        ti.atomic_min(t_out[ids[k]], stop_fraction(
                            x0, x1, n, plane, 1.0 if k < first else -1.0, ids[k]))
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):      # which plane stopped each vertex (the gradient's)
        ids, kind = cl.ids[c], cl.kind[c]
        if log.on[None] and pl.delta[c] != 0.0:
            n = pl.n[c]
            divided, plane, first = dividing_plane(ids, kind, n, x0, x1)
            if divided:
                for k in ti.static(range(4)):
                    t = stop_fraction(x0, x1, n, plane, 1.0 if k < first else -1.0, ids[k])
                    if inv_mass[ids[k]] > 0.0 and t < 1.0 and \
                            ti.abs(t - t_out[ids[k]]) <= 1e-12 * t:
                        # one plane a vertex (where planes tie, as a flat layer's do
                        # for a vertex above it, whichever comes first)
                        if ti.atomic_add(log.claimed[ids[k]], 1) == 0:
                            log.keep(ids[k], ids, kind + pl.surface[c], k)
    cut = 0
    ti.loop_config(serialize=ti.static(serial(x1)))
    for p in range(x1.shape[0]):
        if t_out[p] < 1.0:
            moved = x0[p] + t_out[p] * (x1[p] - x0[p])
            v1[p] *= t_out[p]
            x1[p] = moved
            cut += 1
    return cut


class _CutLog:
    """A log of a step's cuts: ``columns`` (the fields of a row, ``capacity`` rows),
    ``count`` (every row it was given; past the capacity none is kept) and ``on``
    (whether it keeps)."""

    def __init__(self, capacity, columns):
        self.capacity, self.columns = capacity, columns
        self.count = ti.field(ti.i32, shape=())
        self.on = ti.field(ti.i32, shape=())

    def entries(self):
        """The kept rows as NumPy arrays, a column each."""
        k = min(int(self.count[None]), self.capacity)
        return tuple(f.to_numpy()[:k] for f in self.columns)


@ti.data_oriented
class TruncationLog(_CutLog):
    """The fail-safe's cuts of one step, kept where ``on`` is set (a gradient's runs:
    ``tcloth/grad/frozen.py``): each cut vertex (``particle``), the candidate whose
    dividing plane stopped it (``ids``, ``kind`` plus ``normals.SURFACE`` where its
    plane took the surfaces' normal) and its slot in it (``slot``), one a
    vertex (``claimed``, n particles). ``count`` counts them all; past ``capacity``
    they are not kept."""

    def __init__(self, capacity, n):
        self.claimed = ti.field(ti.i32, shape=n)
        self.particle, self.kind, self.slot = (ti.field(ti.i32, shape=capacity)
                                               for _ in range(3))
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        super().__init__(capacity, (self.particle, self.ids, self.kind, self.slot))

    @ti.func
    def keep(self, p, ids, kind, slot):
        c = ti.atomic_add(self.count[None], 1)
        if c < self.capacity:
            self.particle[c], self.ids[c], self.kind[c], self.slot[c] = p, ids, kind, slot


@ti.data_oriented
class SweepLog(_CutLog):
    """The cuts of a step's first collider sweep, kept where ``on`` is set (a gradient's
    runs: ``tcloth/grad/frozen.py``): each cut's particle, collider row, kind (PATH: the
    particle ends at x0 + tau (x1 - x0), where the path meets the collider's offset
    surface; START: at x0, where it started within the thickness or inside) and tau.
    ``count`` counts them all; past ``capacity`` they are not kept."""

    def __init__(self, capacity):
        self.particle, self.row, self.kind = (ti.field(ti.i32, shape=capacity)
                                              for _ in range(3))
        self.tau = ti.field(runtime.real(), shape=capacity)
        super().__init__(capacity, (self.particle, self.row, self.kind, self.tau))

    @ti.func
    def keep(self, p, row, kind, tau):
        if self.on[None]:
            c = ti.atomic_add(self.count[None], 1)
            if c < self.capacity:
                self.particle[c], self.row[c], self.kind[c], self.tau[c] = p, row, kind, tau


@ti.func
def _stop(p, at, n, u, dt, x1, v1, stop_normal):
    """Particle p stopped at ``at`` (at the step's start, in the frame of a collider moving
    at u, outward normal n there): it ends at ``at`` carried by the collider, its velocity
    into the collider removed, and its stop_normal set to n."""
    x1[p] = at + dt * u
    vn = (v1[p] - u).dot(n)
    if vn < 0.0:
        v1[p] -= vn * n
    stop_normal[p] = n


@ti.func
def _offset_stop(table: ti.template(), shape: ti.template(), col, start, d, phi0, hit, t0):
    """How far along the unit direction d from ``start`` (distance phi0 >= 0 from the
    collider, whose surface the ray meets at ``hit``) a stopped path ends: where it comes
    within the collider's thickness of the surface, or, from a start already inside the
    thickness, where it started (BACK_OFF at the least). Its contact penalty is then no
    larger than at its start or the offset surface's zero: a stop adds no energy. The
    distance along a line to a convex shape is convex, so it crosses that depth once
    before ``hit``: bisection."""
    target = ti.max(ti.min(col.thickness, phi0), BACK_OFF)
    lo, hi = 0.0, hit
    if phi0 > target:
        for _ in range(STOP_BISECTIONS):
            mid = 0.5 * (lo + hi)
            phi, normal = table.distance(shape, col, start + mid * d, t0)
            if phi >= target:
                lo = mid
            else:
                hi = mid
    return lo


@ti.func
def sweep_colliders(table, inv_mass, x0, x1, v1, t0, dt, stop_normal, log: ti.template(),
                    keep: ti.template()):
    """Each free particle's path from x0 to x1 against every switched-on collider, in the
    collider's frame (it moves by dt times its velocity): a path from outside that enters
    it ends at the entry, riding with the collider, its velocity into it removed; a
    particle that started inside and would end deeper stays where it was relative to it.
    Returns how many paths were cut (a mesh field's: ``field_sweep.py``);
    ``stop_normal`` gets the collider's outward normal at the stop of each particle cut."""
    clamped = 0
    ti.loop_config(serialize=ti.static(serial(x1)))
    for p in range(x1.shape[0]):
        if inv_mass[p] > 0.0:
            for g in ti.static(table.groups):
                # a certified mesh's paths are kept off it by its pairs' planes
                # (``obstacle.py``), a field's by its own sweep
                if ti.static(SHAPES[g.shape].meshed and table.fields > 0):
                    clamped += field_paths(table, g, p, x0, x1, v1, t0, dt, stop_normal, BACK_OFF)
                if ti.static(not SHAPES[g.shape].meshed):
                    for k in range(g.first, g.first + g.count):
                        col = table.data[k]
                        if col.stiffness > 0.0:
                            u = col.velocity
                            start = x0[p]
                            rel = x1[p] - dt * u - start
                            length = rel.norm()
                            phi0, n0 = table.distance(g.shape, col, start, t0)
                            entered = False
                            if phi0 >= 0.0 and length > phi0:
                                d = rel / length
                                hit = table.ray_hit(g.shape, col, start, d, t0)
                                if 0.0 <= hit < length - BACK_OFF:
                                    stop = _offset_stop(table, g.shape, col, start, d, phi0,
                                                        hit, t0)
                                    entry = start + stop * d
                                    _phi, n = table.distance(g.shape, col, entry, t0)
                                    _stop(p, entry, n, u, dt, x1, v1, stop_normal)
                                    entered = True
                                    if ti.static(keep):
                                        log.keep(p, k, PATH if stop > 0.0 else START,
                                                 stop / length)
                            if not entered:
                                # a path that ends inside without a hit the ray cast
                                # resolves (a start on the surface within rounding), or
                                # one that started inside and goes deeper: the particle
                                # stays where it was
                                phi1, _n1 = table.distance(g.shape, col, x1[p], t0 + dt)
                                if phi1 < ti.min(phi0, 0.0):
                                    _stop(p, start, n0, u, dt, x1, v1, stop_normal)
                                    entered = True
                                    if ti.static(keep):
                                        log.keep(p, k, START, 0.0)
                            if entered:
                                clamped += 1
    return clamped


@ti.kernel
def sweep_colliders_kernel(table: ti.template(), inv_mass: ti.template(), x0: ti.template(),
                           x1: ti.template(), v1: ti.template(), t0: float, dt: float,
                           stop_normal: ti.template(), first: ti.template(),
                           log: ti.template()) -> ti.i32:
    """``sweep_colliders``; ``first``: stop_normal = 0 before (the step's first sweep), and its
    cuts kept in ``log`` while it is on."""
    cut = 0
    if ti.static(first):
        ti.loop_config(serialize=ti.static(serial(stop_normal)))
        for p in range(stop_normal.shape[0]):
            stop_normal[p] = ti.Vector([0.0, 0.0, 0.0])
        cut = sweep_colliders(table, inv_mass, x0, x1, v1, t0, dt, stop_normal, log, True)
    else:
        cut = sweep_colliders(table, inv_mass, x0, x1, v1, t0, dt, stop_normal, log, False)
    return cut
